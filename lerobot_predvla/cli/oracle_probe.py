"""`predvla oracle-probe`: a linear probe of the front end's visual features for the objects' poses relative to
the gripper, beyond what proprioception explains (experiments/oracle_probe.py).

  predvla oracle-probe --hdf5-root outputs/libero_object_table2/hdf5 --suite libero_object \\
      --dataset-root outputs/libero_object_table2/dataset_features --out results/oracle/probe

Replays every demonstration's saved simulator states (physics only, minutes for 500 demonstrations), then fits the
ridge regressions; writes OUT/probe.json and OUT/probe.md.
"""

import argparse
import shlex
import sys
from pathlib import Path

from lerobot_predvla.data.libero_hdf5 import LiberoDataError
from lerobot_predvla.experiments.oracle_probe import run_probe, write_report


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "oracle-probe", help="linear probe of the visual features for object poses beyond proprioception",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--hdf5-root", type=Path, required=True, help="Directory with <suite>/*_demo.hdf5.")
    parser.add_argument("--suite", default="libero_object")
    parser.add_argument("--dataset-root", type=Path, required=True,
                        help="The dataset `predvla convert` wrote from them (or its features-only copy).")
    parser.add_argument("--out", type=Path, required=True, help="Directory for probe.json and probe.md.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        result = run_probe(args.hdf5_root, args.suite, args.dataset_root)
    except (LiberoDataError, ValueError, FileNotFoundError) as err:
        print(f"predvla oracle-probe: error: {err}", file=sys.stderr)
        return 2
    write_report(result, args.out, "predvla " + shlex.join(sys.argv[1:]))
    print((args.out / "probe.md").read_text())
    return 0
