"""`python -m research.divergence`: where a PredVLA checkpoint's exact open loop leaves the demonstrations, in the
simulator.

For each task, the first --demos demonstrations of its hdf5 file are started from their own first MuJoCo state and
the checkpoint's exact open-loop actions (er_iterations=0, unnormalised by its postprocessor) are run up to --cap
steps, beside the demonstration's own actions replayed and another demonstration's plan replayed blind. Writes
OUT/task<k>.png (end effector, gripper, distances to the demonstration with its phases shaded, offline action
error and the demonstrations' action envelope), OUT/divergence.json and OUT/summary.md (its main numbers as
markdown tables). Physics only, no rendering.

  python -m research.divergence --checkpoint checkpoints/predvla_libero_object_table2 \\
    --hdf5-root outputs/libero_object_table2/hdf5 --tasks 1,4,7 --demos 3 --out results/.../divergence
"""

import argparse
import sys
from pathlib import Path

from lerobot_predvla.cli.demos import task_ids
from research.divergence.report import run as run_divergence

COMMAND = "python -m research.divergence"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=COMMAND, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", type=Path, required=True, help="a PredVLA pretrained_model directory")
    p.add_argument("--hdf5-root", type=Path, required=True, help="demonstrations root (files in ROOT/SUITE/)")
    p.add_argument("--suite", default="libero_object")
    p.add_argument("--tasks", type=task_ids, required=True, help="task ids, e.g. 1,4,7")
    p.add_argument("--demos", type=int, default=3, help="demonstrations simulated per task (the file's first)")
    p.add_argument("--cap", type=int, default=600, help="open-loop step cap (default 600, the evaluation's)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--merge", action="store_true",
                   help="keep the other tasks of an existing OUT/divergence.json (same checkpoint, demonstrations and "
                   "cap) and add or replace the tasks run now")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.demos < 1 or args.cap < 1:
        print(f"{COMMAND}: error: --demos and --cap must be >= 1", file=sys.stderr)
        return 2
    if not (args.checkpoint / "config.json").is_file():
        print(f"{COMMAND}: error: {args.checkpoint}: no config.json", file=sys.stderr)
        return 2
    run_divergence(args.checkpoint, args.hdf5_root, args.tasks, args.demos, args.cap, args.out, args.suite,
                   merge=args.merge)
    print(f"wrote {args.out / 'divergence.json'} and task figures to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
