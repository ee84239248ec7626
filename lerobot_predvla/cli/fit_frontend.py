"""`predvla fit-frontend`: fit the frozen front end's PCA bases on LIBERO demonstrations."""

import argparse
import sys
from dataclasses import fields
from pathlib import Path

from lerobot_predvla.frontend.fitting import FitFrontendConfig, fit_frontend, variance_summary
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec
from lerobot_predvla.frontend.vision import PRECISIONS, VisionWeights, VisionWeightsError
from lerobot_predvla.libero.protocol import SUITES
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

CONFIG_DEFAULTS = {f.name: f.default for f in fields(PredVLAConfig)}
# Errors that are the user's input, reported in one line with a non-zero exit.
INPUT_ERRORS = (ValueError, OSError, VisionWeightsError)
LANGUAGE_SOURCES = ("demos", "libero")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "fit-frontend",
        help="Fit the frozen front end's PCA bases on LIBERO hdf5 demonstrations.",
        description=__doc__,
    )
    parser.add_argument("--hdf5-root", type=Path, required=True, help="Directory with <suite>/*_demo.hdf5.")
    parser.add_argument("--suites", default=",".join(SUITES), help="Comma-separated suites to pool.")
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
    parser.add_argument(
        "--language-from", choices=LANGUAGE_SOURCES, default="demos",
        help="Instructions the language PCA is fitted on: 'demos' (default; one per pooled demonstration) or "
        "'libero' (all 40 instructions of LIBERO's four suites from its task list, Section 4.1; use it when "
        "the demonstrations cover fewer suites: one task alone gives all-zero language features).",
    )
    parser.add_argument("--out", type=Path, required=True, help="Output directory of the artefact.")
    parser.set_defaults(func=run)


def _language_instructions(source: str) -> tuple[str, ...] | None:
    if source == "demos":
        return None
    from lerobot_predvla.libero.env import libero_instructions

    return libero_instructions()


def run(args: argparse.Namespace) -> int:
    try:
        cfg = FitFrontendConfig(
            hdf5_root=args.hdf5_root,
            suites=tuple(s.strip() for s in args.suites.split(",") if s.strip()),
            vision_weights=VisionWeights.parse(args.vision_weights, args.vision_seed),
            language_dim=args.language_dim,
            vision_dim_per_camera=args.vision_dim_per_camera,
            precision=args.precision,
            preprocessing=PreprocessingSpec(image_size=args.image_size),
            frame_stride=args.frame_stride,
            batch_size=args.batch_size,
            language_instructions=_language_instructions(args.language_from),
        )
        artefact = fit_frontend(cfg)
        artefact.save(args.out)
    except INPUT_ERRORS as err:
        print(f"predvla fit-frontend: error: {err}", file=sys.stderr)
        return 2
    fit = artefact.fit
    print(
        f"fitted front end on {fit['num_demos']} demos / {fit['num_frames']} frames of {', '.join(cfg.suites)} "
        f"({fit['num_distinct_instructions']} distinct instructions) in {fit['seconds']} s -> {args.out}"
    )
    print(variance_summary(artefact))
    return 0
