"""How episodes start: the spread of the arm's initial joint angles and of the objects' placements, over the
benchmark's official init states and over randomised resets (`predvla demos`, `--env.init_states=false`).

`python -m lerobot_predvla.sims.libero.start_spread --suite libero_object --tasks 0,2 [--init-noise 0.02] [--n 20]`
`python -m lerobot_predvla.sims.libero.start_spread --suite libero_object --demos HDF5_ROOT [--out start_spread.json]`
(the recorded demonstrations' own first states beside the official init states, every task of the suite)

Demonstrations cover only the starts they were recorded from: on libero_object the official init states and the
randomised resets place the objects alike (a few mm), but the official states also start the arm with robosuite's
default joint noise (`OFFICIAL_INIT_NOISE`), which LIBERO's ControlEnv leaves out unless `--init-noise` asks for it.
"""

import argparse
import sys
from pathlib import Path

import h5py
import numpy as np
from tqdm import tqdm

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.env import make_env, num_tasks, official_init_states, random_reset, task_spec
from lerobot_predvla.sims.libero.hdf5_layout import task_file
from lerobot_predvla.utils.io import atomic_write_json

RESET_SEED = 1000  # randomised resets start from this seed, away from the demonstrations' (`predvla demos`)


def _joints(env) -> np.ndarray:
    robot = env.env.robots[0]
    return env.env.sim.data.qpos[robot._ref_joint_pos_indexes].copy()


def _placements(env) -> dict[str, np.ndarray]:
    inner = env.env
    return {name: inner.sim.data.body_xpos[inner.obj_body_id[name]][:2].copy() for name in inner.objects_dict}


def _spread(rows: list[tuple[np.ndarray, dict]]) -> dict:
    """Mean over the arm's joints of their std across starts (rad), per object the mean over x, y of its std (m),
    and per object the mean over x, y of its mean position (m)."""
    objects = rows[0][1]
    return {
        "starts": len(rows),
        "joint_std": float(np.std([j for j, _ in rows], axis=0).mean()),
        "object_std": {o: float(np.std([p[o] for _, p in rows], axis=0).mean()) for o in objects},
        "object_mean": {o: np.mean([p[o] for _, p in rows], axis=0).round(4).tolist() for o in objects},
    }


def start_spread(suite: str, task_id: int, n: int = 20, init_noise: float = 0.0) -> dict[str, dict]:
    """Per start kind ("official", "randomised"): the mean over the arm's joints of their std across `n` starts
    (rad), and per object the mean over x, y of its std (m)."""
    env = make_env(task_spec(suite, task_id), init_noise=init_noise)
    starts: dict[str, list[tuple[np.ndarray, dict]]] = {"official": [], "randomised": []}
    init_states = official_init_states(suite, task_id)
    for k in range(n):
        env.reset()
        env.set_init_state(init_states[k % len(init_states)])
        starts["official"].append((_joints(env), _placements(env)))
        random_reset(env, RESET_SEED + k)
        starts["randomised"].append((_joints(env), _placements(env)))
    env.close()
    return {kind: _spread(rows) for kind, rows in starts.items()}


def demo_start_spread(hdf5_root: Path, suite: str, task_id: int) -> dict[str, dict]:
    """The recorded demonstrations' first simulator states (`states[0]` of each demo in the task's hdf5 file) beside
    the task's official init states, as `start_spread` measures them ("demonstrations", "official")."""
    spec = task_spec(suite, task_id)
    path = task_file(hdf5_root, spec)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no demonstrations of {suite} task {task_id} "
                                "(expected `predvla demos` output)")
    with h5py.File(path, "r") as f:
        firsts = [f["data"][name]["states"][0] for name in sorted(f["data"], key=lambda k: int(k.split("_")[-1]))]
    env = make_env(spec)
    starts: dict[str, list] = {"demonstrations": [], "official": []}
    env.reset()
    for kind, states in (("demonstrations", firsts), ("official", list(official_init_states(suite, task_id)))):
        for state in states:
            env.set_init_state(state)
            starts[kind].append((_joints(env), _placements(env)))
    env.close()
    return {kind: _spread(rows) for kind, rows in starts.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="libero_object", choices=SUITES)
    parser.add_argument("--tasks", default="0", help="comma-separated task ids")
    parser.add_argument("--n", type=int, default=20, help="starts of each kind")
    parser.add_argument("--init-noise", type=float, default=0.0,
                        help="the randomised resets' initial joint noise (std, rad), as `predvla demos --init-noise`")
    parser.add_argument("--demos", type=Path, default=None,
                        help="root of `predvla demos` hdf5 files: compare every task's demonstrations' first states "
                             "with its official init states instead")
    parser.add_argument("--out", type=Path, default=None, help="with --demos: write the table as JSON here")
    args = parser.parse_args(argv)
    if args.demos is not None:
        return print_demo_spread(args.demos, args.suite, args.out)
    try:
        tasks = [int(t) for t in args.tasks.split(",") if t.strip()]
    except ValueError:
        parser.error(f"--tasks expects comma-separated integers, got {args.tasks!r}")
    for task_id in tasks:
        spread = start_spread(args.suite, task_id, args.n, args.init_noise)
        print(f"{args.suite}/{task_id} {task_spec(args.suite, task_id).name}: std over {args.n} starts")
        print(f"  {'':28} {'official':>10} {'randomised':>10}")
        print(f"  {'arm joints (rad)':28} {spread['official']['joint_std']:>10.4f} "
              f"{spread['randomised']['joint_std']:>10.4f}")
        for name, std in spread["official"]["object_std"].items():
            print(f"  {name + ' x, y (m)':28} {std:>10.4f} {spread['randomised']['object_std'][name]:>10.4f}")
    return 0


def print_demo_spread(hdf5_root: Path, suite: str, out: Path | None) -> int:
    try:
        table = {task_id: demo_start_spread(hdf5_root, suite, task_id)
                 for task_id in tqdm(range(num_tasks(suite)), desc=f"{suite} starts", unit="task")}
    except FileNotFoundError as err:
        print(f"start_spread: error: {err}", file=sys.stderr)
        return 2
    print(f"{suite}: std over starts, demonstrations (first states) vs official init states")
    print(f"{'task':>4}  {'joints demos':>12}  {'joints official':>15}  {'objects demos':>13}  "
          f"{'objects official':>16}")
    for task_id, row in table.items():
        demos, official = row["demonstrations"], row["official"]
        print(f"{task_id:>4}  {demos['joint_std']:>12.4f}  {official['joint_std']:>15.4f}  "
              f"{np.mean(list(demos['object_std'].values())):>13.4f}  "
              f"{np.mean(list(official['object_std'].values())):>16.4f}")
    if out is not None:
        atomic_write_json(out, {"suite": suite, "hdf5_root": str(hdf5_root), "tasks": table})
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
