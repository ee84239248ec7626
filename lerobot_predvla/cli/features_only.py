"""`predvla features-only`: a converted dataset's training copy without camera frames (same samples, no decoding)."""

import argparse
import sys
from pathlib import Path

from lerobot_predvla.data.features_only import features_only_copy


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "features-only",
        help="copy a converted dataset without its camera frames, for training (no video decoding per sample)",
        description=__doc__,
    )
    parser.add_argument("--dataset-root", type=Path, required=True, help="Dataset written by `predvla convert`.")
    parser.add_argument("--out", type=Path, required=True, help="Root of the copy to create (must not exist).")
    parser.add_argument("--repo-id", default=None, help="Repo id of the copy (default local/<out name>).")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        copy = features_only_copy(args.dataset_root, args.out, args.repo_id)
    except (ValueError, OSError) as err:
        print(f"predvla features-only: error: {err}", file=sys.stderr)
        return 2
    print(f"{copy.root}: {copy.meta.total_episodes} episodes, {copy.meta.total_frames} frames, features "
          f"{sorted(copy.meta.features)}")
    return 0
