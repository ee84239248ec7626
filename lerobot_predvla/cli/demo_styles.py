"""`predvla demo-styles`: scripted against teleop demonstrations (and teleop from shifted placements), measured on a
sample: success, lengths, no-op steps, end-effector path spread at matched phase, placement spread, and one teleop
plan replayed blind. Physics only; writes OUT/report.json, report.md and styles.png.

  predvla demo-styles --tasks 0,1,2 --per-task 10 --out results/demonstrations
"""

import argparse
import shlex
import sys
from pathlib import Path

from tqdm import tqdm

from lerobot_predvla.cli.blind_replay import _ints
from lerobot_predvla.sims.libero.blind_replay import task_path
from lerobot_predvla.sims.libero.demo_styles import VARIANTS, run

DEFAULT_OUT = Path("results/demonstrations")
COMMITTED_BLIND = Path("results/blind_replay")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("demo-styles", help="measure scripted against teleop demonstrations on a sample",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", type=_ints("--tasks"), default=[0, 1, 2],
                   help="libero_object task ids (default 0-2); the first one's plan is replayed blind")
    p.add_argument("--per-task", type=int, default=10, help="attempts per task and variant (default 10)")
    p.add_argument("--seed", type=int, default=0, help="demonstration seed, as `predvla demos --seed` (default 0)")
    p.add_argument("--blind-states", type=_ints("--blind-states"), default=list(range(1, 20)),
                   help="official init states the teleop plan from state 0 is replayed on (default 1-19)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    if args.per_task < 2:
        raise SystemExit(f"--per-task must be >= 2 (a spread needs two demonstrations), got {args.per_task}")
    committed = task_path(COMMITTED_BLIND, "libero_object", args.tasks[0])
    if not committed.is_file():
        raise SystemExit(f"{committed} is missing: the scripted plan's blind replay of task {args.tasks[0]} "
                         "(`predvla blind-replay --suites libero_object`) is the comparison")
    command = shlex.join(["predvla", *sys.argv[sys.argv.index("demo-styles"):]]) if "demo-styles" in sys.argv \
        else "predvla demo-styles"
    with tqdm(total=len(args.tasks) * len(VARIANTS) * args.per_task, desc="episodes", unit="episode") as bar:
        report = run(args.tasks, args.per_task, args.seed, tuple(args.blind_states), committed, args.out, command,
                     progress=lambda: bar.update(1))
    print((args.out / "report.md").read_text())
    print(f"wrote {args.out}/report.json, report.md, styles.png ({report['seconds']} s)")
    return 0
