"""`predvla fit-frontend`: fit the frozen front end's PCA bases on LIBERO demonstrations or a LeRobot dataset."""

import argparse
import sys
from dataclasses import fields
from pathlib import Path

import torch

from lerobot_predvla.columns import SUITES
from lerobot_predvla.data.dataset_fitting import FitDatasetFrontendConfig, fit_frontend_on_dataset
from lerobot_predvla.data.fitting import FitFrontendConfig, fit_frontend, variance_summary
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec
from lerobot_predvla.frontend.vision import PRECISIONS, VisionWeights, VisionWeightsError
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.sims.libero.env import libero_instructions

CONFIG_DEFAULTS = {f.name: f.default for f in fields(PredVLAConfig)}
# Errors that are the user's input, reported in one line with a non-zero exit.
INPUT_ERRORS = (ValueError, OSError, VisionWeightsError)
LANGUAGE_SOURCES = ("demos", "libero")
# Options that are fields of the same name of both fit configs.
ENCODING_OPTIONS = ("language_dim", "vision_dim_per_camera", "precision", "frame_stride", "batch_size")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fit-frontend",
        help="fit the frozen front end's PCA bases on LIBERO hdf5 demonstrations or a LeRobot dataset",
        description=__doc__,
    )
    parser.add_argument(
        "--hdf5-root", type=Path, action="append", default=None,
        help="Directory with <suite>/*_demo.hdf5; repeat it for suites made in different places (each suite is read "
        "from the one root that has its folder).",
    )
    parser.add_argument(
        "--suites", default=",".join(SUITES),
        help="Comma-separated suites whose demonstrations are pooled: one joint fit of the PCA bases on all their "
        "frames, as the paper fits them on all four suites (default: all four).",
    )
    add_dataset_source_arguments(parser)
    parser.add_argument(
        "--vision-weights", default="imagenet",
        help="ResNet18 weights: 'imagenet' (paper; needs the torchvision download or cache), a .pth state "
        "dict, or 'random' (seeded frozen initialisation for offline runs).",
    )
    parser.add_argument("--vision-seed", type=int, default=0, help="Seed of --vision-weights random.")
    parser.add_argument(
        "--precision", choices=PRECISIONS, default="fp32",
        help="ResNet18 precision: fp32 (default), or bf16 (faster only with native bfloat16, e.g. AMX).",
    )
    parser.add_argument("--image-size", type=int, default=PreprocessingSpec.image_size, help="Resize side.")
    parser.add_argument("--language-dim", type=int, default=CONFIG_DEFAULTS["language_dim"])
    parser.add_argument("--vision-dim-per-camera", type=int, default=CONFIG_DEFAULTS["vision_dim_per_camera"])
    parser.add_argument("--frame-stride", type=int, default=1, help="Fit the visual PCA on every n-th frame.")
    parser.add_argument("--batch-size", type=int, default=64, help="Images per ResNet18 forward pass.")
    add_threads_argument(parser)
    parser.add_argument(
        "--language-from", choices=LANGUAGE_SOURCES, default="demos",
        help="Instructions the language PCA is fitted on: 'demos' (default; one per pooled demonstration) or "
        "'libero' (all 40 instructions of LIBERO's four suites from its task list, Section 4.1; use it when "
        "the demonstrations cover fewer suites: one task alone gives all-zero language features). With "
        "--dataset-root/--dataset-repo-id the language PCA is fitted on the dataset's tasks: leave it at 'demos'.",
    )
    parser.add_argument("--out", type=Path, required=True, help="Output directory of the artefact.")
    parser.set_defaults(func=run)


def _encoding_settings(args: argparse.Namespace) -> dict:
    """The settings of both inputs' fits (`FitFrontendConfig`, `FitDatasetFrontendConfig`): encoders, PCA sizes and
    frame sampling, from the options of the same names."""
    return {
        "vision_weights": VisionWeights.parse(args.vision_weights, args.vision_seed),
        **{name: getattr(args, name) for name in ENCODING_OPTIONS},
    }


def _language_instructions(source: str) -> tuple[str, ...] | None:
    if source == "demos":
        return None
    return libero_instructions()


def add_dataset_source_arguments(parser: argparse.ArgumentParser) -> None:
    """The options naming an existing LeRobot v3 dataset as input (shared with `predvla convert`)."""
    parser.add_argument("--dataset-root", type=Path, default=None, help="Local root of a LeRobot v3 dataset.")
    parser.add_argument(
        "--dataset-repo-id", default=None,
        help="Hub repo id of a LeRobot dataset, loaded through LeRobot (needs the Hub); with --dataset-root, "
        "the id of that local copy.",
    )
    parser.add_argument(
        "--cameras", default=None,
        help="Comma-separated camera keys to encode, in order (default: every camera of the dataset for "
        "fit-frontend, the front end's cameras for convert).",
    )


def add_threads_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--threads", type=int, default=None,
        help="Torch threads of the image encoder (default: torch's setting, e.g. OMP_NUM_THREADS); the features "
        "are the same for any count.",
    )


def use_threads(args: argparse.Namespace) -> bool:
    """Apply `--threads` (the language encoder keeps one thread: frontend/language.py); False, with the error
    printed, when it is not a positive count."""
    if args.threads is None:
        return True
    if args.threads < 1:
        print(f"predvla: error: --threads must be >= 1, got {args.threads}", file=sys.stderr)
        return False
    torch.set_num_threads(args.threads)
    return True


def dataset_source_given(args: argparse.Namespace) -> bool:
    """Whether the input is a LeRobot dataset; mixing it with LIBERO hdf5 input is an error."""
    given = args.dataset_root is not None or args.dataset_repo_id is not None
    if given and args.hdf5_root is not None:
        raise ValueError("--hdf5-root and --dataset-root/--dataset-repo-id are alternatives; give one.")
    return given


def parse_cameras(spec: str | None) -> list[str] | None:
    return None if spec is None else [c.strip() for c in spec.split(",") if c.strip()]


def run(args: argparse.Namespace) -> int:
    if not use_threads(args):
        return 2
    try:
        if dataset_source_given(args):
            if args.language_from != "demos":
                raise ValueError("--language-from applies to --hdf5-root; a dataset's language PCA uses its tasks.")
            return run_on_dataset(args)
        if args.hdf5_root is None:
            raise ValueError("give --hdf5-root (LIBERO hdf5) or --dataset-root/--dataset-repo-id (LeRobot dataset).")
        cfg = FitFrontendConfig(
            hdf5_roots=tuple(args.hdf5_root),
            suites=tuple(s.strip() for s in args.suites.split(",") if s.strip()),
            **_encoding_settings(args),
            preprocessing=PreprocessingSpec(image_size=args.image_size),
            language_instructions=_language_instructions(args.language_from),
        )
        artefact = fit_frontend(cfg)
        artefact.save(args.out)
    except INPUT_ERRORS as err:
        print(f"predvla fit-frontend: error: {err}", file=sys.stderr)
        return 2
    fit = artefact.fit
    per_suite = ", ".join(f"{suite} {c['num_demos']}/{c['num_frames']}" for suite, c in fit["by_suite"].items())
    print(
        f"fitted front end on {fit['num_demos']} demos / {fit['num_frames']} frames ({per_suite}; visual PCA on "
        f"{fit['num_frames_fitted']} frames) with {fit['num_distinct_instructions']} distinct instructions in "
        f"{fit['seconds']} s -> {args.out}"
    )
    print(variance_summary(artefact))
    return 0


def run_on_dataset(args: argparse.Namespace) -> int:
    """`--dataset-root/--dataset-repo-id`: fit on an existing LeRobot dataset; errors are left to `run`."""
    cfg = FitDatasetFrontendConfig(
        **_encoding_settings(args),
        dataset_root=args.dataset_root,
        dataset_repo_id=args.dataset_repo_id,
        cameras=parse_cameras(args.cameras),
        image_size=args.image_size,
    )
    artefact = fit_frontend_on_dataset(cfg)
    artefact.save(args.out)
    fit = artefact.fit
    print(
        f"fitted front end on {fit['num_demos']} episodes / {fit['num_frames']} frames of {fit['dataset']} "
        f"(cameras {', '.join(fit['cameras'])}; {fit['num_distinct_instructions']} distinct instructions) in "
        f"{fit['seconds']} s -> {args.out}"
    )
    print(variance_summary(artefact))
    return 0
