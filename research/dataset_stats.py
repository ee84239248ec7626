"""A demonstration dataset's statistics, read from its hdf5 files: per task and over all, how many demonstrations, their
lengths (mean, min, max, how many exceed the training sequence length and are cut there) and the fraction of no-op
steps (OpenVLA's filter, `research.demo_styles.noop_mask`). Writes one JSON file (docs/research/demonstrations.md).

  python -m research.dataset_stats outputs/libero_object_teleop/hdf5/libero_object \
    --label "D2 teleop (predvla demos --style teleop --diversity 1.0, seed 0, 50 per task)" \
    --out results/demonstrations/teleop/dataset_stats.json
"""

import argparse
import sys
from pathlib import Path

import h5py
import numpy as np

from lerobot_predvla.utils.io import atomic_write_json
from research.demo_styles import NOOP_THRESHOLD, noop_mask

DEMO_SUFFIX = "_demo.hdf5"  # `predvla demos` writes <task name>_demo.hdf5 per task
NOOP_RULE = f"motion command |a[:6]| < {NOOP_THRESHOLD:g} and gripper command unchanged (OpenVLA's filter)"


def task_actions(path: Path) -> list[np.ndarray]:
    """Every demonstration's actions in one task file (robomimic layout: data/demo_k/actions)."""
    with h5py.File(path, "r") as f:
        if "data" not in f:
            raise ValueError(f"{path}: no 'data' group; expected a robomimic-layout demonstration file")
        return [f["data"][k]["actions"][()] for k in sorted(f["data"], key=lambda k: int(k.split("_")[-1]))]


def summarise(actions: list[np.ndarray], sequence_length: int, with_min: bool = False) -> dict:
    """Counts of a set of demonstrations (a task's or all of them)."""
    steps = np.array([len(a) for a in actions])
    noop = sum(int(noop_mask(a).sum()) for a in actions)
    return {
        "demos": len(actions),
        "steps_mean": round(float(steps.mean()), 1),
        **({"steps_min": int(steps.min())} if with_min else {}),
        "steps_max": int(steps.max()),
        f"longer_than_{sequence_length}": int((steps > sequence_length).sum()),
        "noop_fraction": round(noop / int(steps.sum()), 4),
    }


def dataset_stats(suite_dir: Path, label: str, sequence_length: int) -> dict:
    files = sorted(suite_dir.glob(f"*{DEMO_SUFFIX}"))
    if not files:
        raise FileNotFoundError(f"{suite_dir}: no *{DEMO_SUFFIX} files (expected `predvla demos --out` ROOT/SUITE)")
    per_task = {path.name.removesuffix(DEMO_SUFFIX): task_actions(path) for path in files}
    everything = [a for actions in per_task.values() for a in actions]
    return {
        "dataset": label,
        "per_task": {task: summarise(actions, sequence_length) for task, actions in per_task.items()},
        "all": {**summarise(everything, sequence_length, with_min=True), "noop_rule": NOOP_RULE},
    }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m research.dataset_stats", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("suite_dir", type=Path, help="one suite's folder of *_demo.hdf5 files")
    parser.add_argument("--label", required=True, help="what the dataset is (written as 'dataset')")
    parser.add_argument("--sequence-length", type=int, default=200,
                        help="training sequence length: demonstrations longer than it are counted (Table 2: 200)")
    parser.add_argument("--out", type=Path, required=True, help="JSON file to write")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        stats = dataset_stats(args.suite_dir, args.label, args.sequence_length)
    except (FileNotFoundError, ValueError) as error:
        print(f"python -m research.dataset_stats: {error}", file=sys.stderr)
        return 2
    atomic_write_json(args.out, stats)
    print(f"{args.out}: {stats['all']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
