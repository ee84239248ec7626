"""`predvla convert`: LIBERO hdf5 suite, or an existing LeRobot dataset, -> LeRobot v3.0 dataset with cached
front-end features."""

import argparse
import sys
from pathlib import Path

import datasets

from lerobot_predvla.cli.fit_frontend import (
    CONFIG_DEFAULTS,
    INPUT_ERRORS,
    add_dataset_source_arguments,
    add_threads_argument,
    dataset_source_given,
    parse_cameras,
    use_threads,
)
from lerobot_predvla.data.conversion import IMAGE_STORAGES, convert_suite
from lerobot_predvla.data.dataset_conversion import convert_dataset
from lerobot_predvla.data.libero_hdf5 import scan_suites
from lerobot_predvla.sims.libero.oracle import fit_oracle


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "convert",
        help="convert a LIBERO hdf5 suite or a LeRobot dataset into a LeRobot dataset with cached PredVLA features",
        description=__doc__,
    )
    parser.add_argument("--hdf5-root", type=Path, default=None, help="Directory with <suite>/*_demo.hdf5.")
    parser.add_argument("--suite", default=None, help="Suite to convert, e.g. libero_object (with --hdf5-root).")
    add_dataset_source_arguments(parser)
    parser.add_argument("--frontend", type=Path, required=True, help="Artefact from `predvla fit-frontend`.")
    parser.add_argument("--out", type=Path, required=True, help="Dataset root to create (must not exist).")
    parser.add_argument(
        "--repo-id", default=None, help="Repo id of the new dataset (default local/<suite> or local/<out name>)."
    )
    parser.add_argument(
        "--image-storage", choices=IMAGE_STORAGES, default="video",
        help="hdf5 only: camera frames as AV1 video (LeRobot default, small, lossy), PNG (lossless, ~5x "
        "larger) or none (the cached features only: what training reads, as `predvla features-only` makes it, "
        "without encoding a video). A LeRobot dataset keeps its own storage.",
    )
    parser.add_argument("--language-dim", type=int, default=CONFIG_DEFAULTS["language_dim"])
    parser.add_argument("--vision-dim-per-camera", type=int, default=CONFIG_DEFAULTS["vision_dim_per_camera"])
    parser.add_argument("--batch-size", type=int, default=64, help="Images per ResNet18 forward pass.")
    add_threads_argument(parser)
    parser.add_argument(
        "--oracle", action="store_true",
        help="hdf5 only, a diagnostic: replace the visual features by the simulator's object poses relative to the "
        "gripper (replayed from the demonstrations' saved states, standardised); writes no camera. Evaluate with "
        "--env.type=predvla_libero --env.oracle=true.",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not use_threads(args):
        return 2
    datasets.disable_progress_bars()  # Our own bar counts frames; the per-episode Map bars are noise.
    common = {
        "frontend_dir": args.frontend, "out": args.out, "repo_id": args.repo_id, "language_dim": args.language_dim,
        "vision_dim_per_camera": args.vision_dim_per_camera, "batch_size": args.batch_size,
    }
    try:
        if dataset_source_given(args):
            if args.oracle:
                raise ValueError("--oracle needs the simulator states of LIBERO hdf5 demonstrations (--hdf5-root).")
            summary = convert_dataset(
                dataset_root=args.dataset_root, dataset_repo_id=args.dataset_repo_id,
                cameras=parse_cameras(args.cameras), **common,
            )
        elif args.hdf5_root is None or args.suite is None:
            raise ValueError("give --hdf5-root and --suite (LIBERO hdf5), or --dataset-root/--dataset-repo-id.")
        else:
            oracle = None
            if args.oracle:
                print("predvla convert: ORACLE front end (a diagnostic): visual features = simulator object poses "
                      "relative to the gripper, not camera images.")
                oracle = fit_oracle(args.suite, scan_suites(args.hdf5_root, [args.suite]))
            summary = convert_suite(
                hdf5_root=args.hdf5_root, suite=args.suite, image_storage=args.image_storage, oracle=oracle, **common
            )
    except INPUT_ERRORS as err:
        print(f"predvla convert: error: {err}", file=sys.stderr)
        return 2
    print(summary)
    return 0
