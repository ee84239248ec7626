"""Wall time of a LIBERO evaluation episode: rendering every step vs every 4th step vs physics only.

Runs the `predvla_libero` environment (LeRobot's LiberoEnv with sparse rendering) with a fixed random
action sequence and prints the mean milliseconds per control step (median over episodes) and the
ratios, all measured in one run:

    python benchmarks/bench_eval_env.py --steps 120 --repeats 3

`render_interval=1` renders both 128 px cameras at every step (what LeRobot's `libero` env does);
`render_interval=4` is PredVLA's refresh; "physics only" renders once at reset.
"""

import argparse
import os
import statistics
import time

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def time_steps(render_interval: int, steps: int, seed: int) -> float:
    """Mean ms per control step over one episode of `steps` steps (environment build and reset excluded).

    The mean, not the median: with sparse rendering 3 of 4 steps are physics only, so the median would hide
    the rendered ones.
    """
    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    cfg = PredVLALiberoEnv(task="libero_object", task_ids=[0], render_interval=render_interval)
    venv = cfg.create_envs(n_envs=1)["libero_object"][0]
    venv.reset(seed=[seed])
    actions = np.random.default_rng(seed).uniform(-0.3, 0.3, (steps, 1, 7)).astype(np.float32)
    durations = []
    for action in actions:
        start = time.perf_counter()
        venv.step(action)
        durations.append(time.perf_counter() - start)
    venv.close()
    return 1000 * statistics.fmean(durations)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=120, help="control steps per episode")
    parser.add_argument("--repeats", type=int, default=3, help="episodes per setting (median of their means)")
    args = parser.parse_args()
    settings = {"render every step": 1, "render every 4th step": 4, "physics only": 10**9}
    results = {name: statistics.median(time_steps(k, args.steps, seed) for seed in range(args.repeats))
               for name, k in settings.items()}
    physics = results["physics only"]
    print(f"{'setting':<24}{'ms/step (mean)':>18}{'x physics':>11}")
    for name, ms in results.items():
        print(f"{name:<24}{ms:>18.1f}{ms / physics:>11.2f}")
    every, fourth = results["render every step"], results["render every 4th step"]
    print(f"sparse rendering speed-up: {every / fourth:.2f}x; "
          f"episode of 280 steps: {every * 0.28:.0f} s vs {fourth * 0.28:.0f} s (physics only {physics * 0.28:.0f} s)")


if __name__ == "__main__":
    main()
