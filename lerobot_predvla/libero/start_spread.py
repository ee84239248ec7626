"""How episodes start: the spread of the arm's initial joint angles and of the objects' placements, over the
benchmark's official init states and over randomised resets (`predvla demos`, `--env.init_states=false`).

`python -m lerobot_predvla.libero.start_spread --suite libero_object --tasks 0,2 [--init-noise 0.02] [--n 20]`

Demonstrations cover only the starts they were recorded from: on libero_object the official init states and the
randomised resets place the objects alike (a few mm), but the official states also start the arm with robosuite's
default joint noise (`OFFICIAL_INIT_NOISE`), which LIBERO's ControlEnv leaves out unless `--init-noise` asks for it.
"""

import argparse
import sys

import numpy as np

from lerobot_predvla.libero.env import make_env, official_init_states, random_reset, task_spec
from lerobot_predvla.libero.protocol import SUITES

RESET_SEED = 1000  # randomised resets start from this seed, away from the demonstrations' (`predvla demos`)


def _joints(env) -> np.ndarray:
    robot = env.env.robots[0]
    return env.env.sim.data.qpos[robot._ref_joint_pos_indexes].copy()


def _placements(env) -> dict[str, np.ndarray]:
    inner = env.env
    return {name: inner.sim.data.body_xpos[inner.obj_body_id[name]][:2].copy() for name in inner.objects_dict}


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
    out = {}
    for kind, rows in starts.items():
        objects = rows[0][1]
        out[kind] = {
            "joint_std": float(np.std([j for j, _ in rows], axis=0).mean()),
            "object_std": {o: float(np.std([p[o] for _, p in rows], axis=0).mean()) for o in objects},
        }
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", default="libero_object", choices=SUITES)
    parser.add_argument("--tasks", default="0", help="comma-separated task ids")
    parser.add_argument("--n", type=int, default=20, help="starts of each kind")
    parser.add_argument("--init-noise", type=float, default=0.0,
                        help="the randomised resets' initial joint noise (std, rad), as `predvla demos --init-noise`")
    args = parser.parse_args(argv)
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


if __name__ == "__main__":
    sys.exit(main())
