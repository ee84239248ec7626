"""Simulator time of one lerobot-eval batch whose episodes end at different steps: finished sub-environments frozen
(`predvla_libero`'s `FreezeFinishedEpisode`) against simulated on (Gymnasium's autoreset starting the episodes that
lerobot-eval discards, as before the freeze), in alternation, with the floor: the same steps of the episodes that
count, one sub-environment at a time.

    python benchmarks/bench_eval_freeze.py --envs 10 --cap 280 --repeats 2
    python benchmarks/bench_eval_freeze.py --checkpoint checkpoints/predvla_libero_object --task 2 --envs 10 --cap 280

libero_object task 0, `render_interval` 4 (error regression's), a fixed random action sequence; sub-environment i's
episode ends at step `cap * (i + 1) / (envs + 1)` (a non-finite action faults it, which ends it as a failure), the
last one at the cap. The policy's time per batch step is the same either way and is left out.

With `--checkpoint`, instead: `lerobot-eval` of that policy (task `--task`, official init states, one batch of
`--envs` episodes), once frozen and once simulated, each in a fresh process; it prints both wall times and checks
that every episode's actions up to its end are the same in both, bit for bit.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def episode_ends(envs: int, cap: int) -> list[int]:
    """The step at which each sub-environment's episode ends: spread over the cap, the last one at it."""
    return [cap * (i + 1) // (envs + 1) for i in range(envs - 1)] + [cap]


def batch_seconds(frozen: bool, envs: int, cap: int, seed: int) -> float:
    """Wall seconds of one batch of `envs` episodes (reset excluded), ends spread as the module says."""
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION

    from lerobot_predvla.sims.libero.env import libero_suite
    from lerobot_predvla.sims.libero.predvla_libero import SparseRenderLiberoEnv, frozen_env

    suite = libero_suite("libero_object")
    factory = frozen_env if frozen else SparseRenderLiberoEnv
    fns = [partial(factory, task_suite=suite, task_id=0, task_suite_name="libero_object", episode_index=i, n_envs=envs,
                   episode_length=cap) for i in range(envs)]
    venv = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
    venv.reset(seed=list(range(seed, seed + envs)), options={NEW_ROLLOUT_OPTION: True})
    ends = episode_ends(envs, cap)[:-1]  # the last one runs to the cap
    actions = np.random.default_rng(seed).uniform(-0.3, 0.3, (cap, envs, 7)).astype(np.float32)
    start = time.perf_counter()
    for step, action in enumerate(actions, start=1):
        for row, end in enumerate(ends):
            if step == end:
                action[row] = np.nan
        venv.step(action)
    seconds = time.perf_counter() - start
    venv.close()
    return seconds


def floor_seconds(envs: int, cap: int, seed: int) -> float:
    """The steps of the counted episodes alone: each episode's steps up to its end, one environment at a time."""
    return sum(batch_seconds(True, 1, end, seed + i) for i, end in enumerate(episode_ends(envs, cap)))


# One lerobot-eval in this process: argv[1] "frozen" or "simulated", argv[2] the .npz for the actions and ends, the
# rest lerobot-eval's arguments.
EVAL_CHILD = """
import sys, time
import gymnasium as gym
import numpy as np
import lerobot_predvla.sims.libero.predvla_libero as predvla_libero
from lerobot.scripts import lerobot_eval

if sys.argv[1] == "simulated":
    predvla_libero.frozen_env = predvla_libero.SparseRenderLiberoEnv
actions, ends, step = [], [], gym.vector.SyncVectorEnv.step

def logged_step(self, batch):
    actions.append(np.array(batch))
    out = step(self, batch)
    ends.append(out[2] | out[3])
    return out

gym.vector.SyncVectorEnv.step = logged_step
out = sys.argv[2]
sys.argv = ["lerobot-eval", *sys.argv[3:]]
start = time.perf_counter()
lerobot_eval.main()
np.savez(out, actions=np.stack(actions), ends=np.stack(ends), seconds=time.perf_counter() - start)
"""


def policy_runs(checkpoint: Path, task: int, envs: int, cap: int) -> None:
    """lerobot-eval of `checkpoint`, frozen and simulated; wall times and whether the counted actions agree."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("frozen", "simulated"):
            arguments = [f"--policy.path={checkpoint}", "--policy.device=cpu", "--env.type=predvla_libero",
                         "--env.task=libero_object", f"--env.task_ids=[{task}]", f"--env.episode_length={cap}",
                         f"--eval.n_episodes={envs}", f"--eval.batch_size={envs}", "--eval.use_async_envs=false",
                         "--seed=0", f"--output_dir={tmp}/{mode}"]
            subprocess.run([sys.executable, "-c", EVAL_CHILD, mode, f"{tmp}/{mode}.npz", *arguments], check=True)
            runs[mode] = dict(np.load(f"{tmp}/{mode}.npz"))
    frozen, simulated = runs["frozen"], runs["simulated"]
    ended = frozen["ends"].any(axis=0)  # an episode that never ended ran to lerobot-eval's last step
    last = np.where(ended, frozen["ends"].argmax(axis=0), len(frozen["ends"]) - 1)
    same = all(np.array_equal(frozen["actions"][: end + 1, row], simulated["actions"][: end + 1, row])
               for row, end in enumerate(last))
    print(f"lerobot-eval, {envs} episodes of task {task}, episodes ending at steps {sorted((last + 1).tolist())}:")
    print(f"frozen {frozen['seconds']:.1f} s, simulated {simulated['seconds']:.1f} s: "
          f"{simulated['seconds'] / frozen['seconds']:.2f}x faster; every episode's actions the same: {same}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", type=int, default=10, help="sub-environments of the batch (lerobot-eval's batch)")
    parser.add_argument("--cap", type=int, default=280, help="control steps of the longest episode")
    parser.add_argument("--repeats", type=int, default=2, help="batches per setting, alternating (median)")
    parser.add_argument("--checkpoint", type=Path, default=None,
                        help="time lerobot-eval of this policy instead, and check its actions agree")
    parser.add_argument("--task", type=int, default=0, help="libero_object task of the --checkpoint evaluation")
    args = parser.parse_args()
    if args.checkpoint is not None:
        policy_runs(args.checkpoint, args.task, args.envs, args.cap)
        return
    times: dict[str, list[float]] = {"frozen": [], "simulated": [], "floor": []}
    for seed in range(args.repeats):
        times["frozen"].append(batch_seconds(True, args.envs, args.cap, seed))
        times["simulated"].append(batch_seconds(False, args.envs, args.cap, seed))
        times["floor"].append(floor_seconds(args.envs, args.cap, seed))
    median = {name: statistics.median(values) for name, values in times.items()}
    for name, seconds in median.items():
        print(f"{name:<10}{seconds:8.1f} s  ({seconds / median['floor']:.2f}x floor)")
    print(f"finished sub-environments frozen: {median['simulated'] / median['frozen']:.2f}x faster per batch "
          f"({args.envs} environments, episodes ending from step {args.cap // (args.envs + 1)} to {args.cap})")


if __name__ == "__main__":
    main()
