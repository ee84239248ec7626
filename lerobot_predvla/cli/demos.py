"""`predvla demos`: scripted-expert LIBERO demonstrations in the original hdf5 layout.

Episodes start from randomised resets (never the official evaluation init states; `--official-init-states`
only measures the expert's success there) and roll out without rendering; only successful ones are kept, and
their 128x128 images are rendered afterwards by replaying the saved states.
"""

import argparse
from pathlib import Path

from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN, HALF_TURN_RULES
from lerobot_predvla.sims.libero.expert.teleop import DEFAULT_STYLE, STYLES
from lerobot_predvla.sims.libero.record import record_demos


def task_ids(text: str) -> list[int]:
    try:
        return [int(t) for t in text.split(",") if t.strip()]
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"--tasks expects comma-separated integers, got {text!r}") from err


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("demos", help="generate scripted-expert LIBERO demonstrations (hdf5)",
                              description=__doc__)
    p.add_argument("--suite", default="libero_object",
                   choices=["libero_spatial", "libero_object", "libero_goal", "libero_10"])
    p.add_argument("--tasks", type=task_ids, default=None, help="task ids, e.g. 0,1 (default: all)")
    p.add_argument("--per-task", type=int, default=10, help="successful demonstrations per task")
    p.add_argument("--max-attempts", type=int, default=None, help="episodes tried per task (default 3x)")
    p.add_argument("--max-steps", type=int, default=None, help="step cap per episode (default: suite cap)")
    p.add_argument("--out", type=Path, default=None, help="root folder; files go to OUT/SUITE/")
    p.add_argument("--no-render", action="store_true",
                   help="only measure expert success: no rendering, no files (then --out is not needed)")
    p.add_argument("--render-interval", type=int, default=1,
                   help="render the cameras every k-th step, repeating the last images in between (default 1: "
                   "every step, LIBERO's layout; 4 = PredVLA's visual refresh, 4x cheaper)")
    p.add_argument("--init-noise", type=float, default=0.0,
                   help="std (rad) of Gaussian noise on the arm's initial joint angles at each reset (default 0: "
                   "LIBERO ControlEnv's fixed start). The benchmark's official init states carry robosuite's "
                   "default, 0.02; demonstrations without it never show the policy an arm that starts elsewhere")
    p.add_argument("--half-turn", choices=HALF_TURN_RULES, default=DEFAULT_HALF_TURN,
                   help="which of a finger direction and its half turn the expert grasps with: the one nearer the "
                   "current fingers (default; every recorded dataset) or the one leaving the wrist joint nearer the "
                   "middle of its range (one wrist branch per task also with --init-noise)")
    p.add_argument("--hold-steps", type=int, default=0,
                   help="idle steps (arm still, gripper open) recorded after each success (default 0: episodes end "
                   "at success, as LIBERO's). A policy rolled out past the demonstrations' end acts untrained; with "
                   "holds it learns to wait while a released object settles")
    p.add_argument("--official-init-states", action="store_true",
                   help="with --no-render only: start attempt k from the benchmark's official init state k instead "
                   "of a randomised reset, to measure the expert where the policies are evaluated (demonstrations "
                   "are never recorded from evaluation states)")
    add_style_arguments(p, "the expert's plan")
    p.add_argument("--placement-spread-cm", type=float, default=0.0,
                   help="std (cm, per axis, truncated at 2 std) of a seeded x, y shift of every movable object after "
                   "each reset (default 0: LIBERO's placements, which spread the objects by a few mm)")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)


def add_style_arguments(p: argparse.ArgumentParser, plan: str) -> None:
    """`--style` and `--diversity`: who executes `plan` (the script or the teleoperator model) and how strongly."""
    p.add_argument("--style", choices=STYLES, default=DEFAULT_STYLE,
                   help=f"who executes {plan}: the script (default) or the teleoperator model "
                   "(curved paths, varying speed, idle stretches, overshoots, regrasps; "
                   "lerobot_predvla/sims/libero/expert/teleop.py)")
    p.add_argument("--diversity", type=float, default=None,
                   help="with --style teleop: how strongly the teleoperator model perturbs the plan (0: the script's "
                   "actions exactly; 1, the default: the committed setting)")


def run(args: argparse.Namespace) -> int:
    return record_demos(args)
