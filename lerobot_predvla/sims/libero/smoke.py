"""Check that every task of the four LIBERO suites builds, resets, loads an init state, steps and
evaluates its goal: `python -m lerobot_predvla.sims.libero.smoke [--suites ...] [--steps N]`."""

import argparse
import sys
import time

import numpy as np

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.env import make_env, num_tasks, official_init_states, random_reset, task_spec


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suites", nargs="+", default=list(SUITES), choices=SUITES)
    parser.add_argument("--steps", type=int, default=20, help="zero-action steps per task")
    args = parser.parse_args(argv)

    failures, start = [], time.time()
    for suite in args.suites:
        for task_id in range(num_tasks(suite)):
            spec = task_spec(suite, task_id)
            t0 = time.time()
            try:
                env = make_env(spec)
                random_reset(env, seed=task_id)
                env.set_init_state(official_init_states(suite, task_id)[0])
                t1 = time.time()
                for _ in range(args.steps):
                    env.step(np.zeros(7))
                step_ms = (time.time() - t1) / args.steps * 1000
                success = env.check_success()
                env.close()
                print(f"ok   {suite}/{task_id:<2} build+reset {t1 - t0:4.1f} s, step {step_ms:4.1f} ms, "
                      f"success={success}  {spec.name}", flush=True)
            except Exception as err:  # report every broken task, not only the first
                failures.append(f"{suite}/{task_id}")
                print(f"FAIL {suite}/{task_id} {spec.name}: {err!r}", flush=True)
    print(f"{len(failures)} failures in {time.time() - start:.0f} s {failures}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
