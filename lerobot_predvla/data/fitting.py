"""Fitting the front end's PCA bases jointly on LIBERO demonstrations (Section 4.1)."""

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from lerobot_predvla.columns import HDF5_CAMERAS, SUITES
from lerobot_predvla.data.libero_hdf5 import DemoRef, read_demo, scan_suites
from lerobot_predvla.frontend.artefact import FrontendArtefact
from lerobot_predvla.frontend.language import LanguageEncoder
from lerobot_predvla.frontend.pca import fit_pca
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec, libero_hdf5_to_lerobot, preprocess_images
from lerobot_predvla.frontend.vision import VisionEncoder, VisionWeights
from lerobot_predvla.utils.versions import package_versions

# The libraries that determine the features, recorded with every fit.
FRONTEND_DISTRIBUTIONS = ("torch", "torchvision", "sentence-transformers", "scikit-learn", "lerobot")


@dataclass
class FitFrontendConfig:
    """Settings of `predvla fit-frontend`.

    Args:
        hdf5_roots: Directories holding one sub-directory of `*_demo.hdf5` files per suite; each suite is read from
            the one root that has its folder (`suite_roots`), so suites made in different places fit together.
        suites: Suites whose demonstrations are pooled: the PCA bases are fitted jointly on all their frames (the
            paper fits them on the training demonstrations of all four suites, Section 4.1).
        vision_weights: ResNet18 weights.
        language_dim: Language PCA components (Table 1: 64).
        vision_dim_per_camera: Visual PCA components per camera (Table 1: 96).
        precision: Precision of the ResNet18 features, "fp32" or "bf16" (faster only with native bfloat16
            hardware; ~4x slower emulated on AVX2-only CPUs); recorded and reused.
        preprocessing: Image preprocessing.
        frame_stride: Use every n-th frame for the visual PCA (1 = all frames).
        batch_size: Images per ResNet18 forward pass.
        language_instructions: Instructions the language PCA is fitted on, one sample each. None (default):
            one per pooled demonstration, as the paper does with the demonstrations of all four suites. With
            demonstrations of fewer suites, pass the benchmark's task list (`libero_instructions()`: all 40
            instructions of the four suites, Section 4.1) so that the basis is the paper's: otherwise one
            task gives all-zero language features and two tasks a rank-1 basis.
    """

    hdf5_roots: tuple[Path, ...]
    vision_weights: VisionWeights
    suites: tuple[str, ...] = SUITES
    language_dim: int = 64
    vision_dim_per_camera: int = 96
    precision: str = "fp32"
    preprocessing: PreprocessingSpec = field(default_factory=PreprocessingSpec)
    frame_stride: int = 1
    batch_size: int = 64
    language_instructions: tuple[str, ...] | None = None


def fit_frontend(cfg: FitFrontendConfig) -> FrontendArtefact:
    """Encode the demonstrations with the frozen encoders and fit the language and per-camera PCA bases."""
    if cfg.frame_stride < 1:
        raise ValueError(f"frame_stride must be >= 1, got {cfg.frame_stride}.")
    start = time.perf_counter()
    refs = scan_suites(cfg.hdf5_roots, list(cfg.suites))
    vision = VisionEncoder(cfg.vision_weights, cfg.precision, batch_size=cfg.batch_size)
    language = LanguageEncoder()

    features: dict[str, list[torch.Tensor]] = {camera: [] for camera in HDF5_CAMERAS}
    total = demonstration_counts(refs, cfg.frame_stride)["num_frames_fitted"]
    with tqdm(total=total, desc="encoding frames", unit="frame") as progress:
        for ref in refs:
            demo = read_demo(ref, cfg.frame_stride)
            for camera, images in demo.images.items():
                pixels = preprocess_images(libero_hdf5_to_lerobot(images), cfg.preprocessing)
                features[camera].append(vision(pixels))
            progress.update(len(demo.action))

    # One instruction embedding per demonstration (each demonstration weighs the same), or per instruction
    # of the given task list.
    demo_instructions = [ref.instruction for ref in refs]
    instructions = list(cfg.language_instructions or demo_instructions)
    missing = sorted(set(demo_instructions) - set(instructions))
    if missing:
        raise ValueError(f"language_instructions lack the demonstrations' instructions {missing}.")
    return fitted_artefact(
        vision, language, instructions, features, cfg.language_dim, cfg.vision_dim_per_camera, cfg.preprocessing, start,
        fit={
            "hdf5_roots": [str(Path(root).resolve()) for root in cfg.hdf5_roots],
            "suites": list(cfg.suites),
            **demonstration_counts(refs, cfg.frame_stride),
            "by_suite": {
                suite: {
                    "hdf5_root": str(ref_group[0].file.parent.parent.resolve()),
                    **demonstration_counts(ref_group, cfg.frame_stride),
                }
                for suite, ref_group in group_by_suite(refs, cfg.suites).items()
            },
            "frame_stride": cfg.frame_stride,
            "num_distinct_instructions": len(set(instructions)),
            "language_fit_on": "task list" if cfg.language_instructions else "demonstrations",
        },
    )


def group_by_suite(refs: list[DemoRef], suites: tuple[str, ...]) -> dict[str, list[DemoRef]]:
    """`refs` by suite (the folder `<root>/<suite>` each file is in), in the order of `suites`."""
    return {suite: [ref for ref in refs if ref.file.parent.name == suite] for suite in suites}


def demonstration_counts(refs: list[DemoRef], frame_stride: int) -> dict[str, int]:
    """Files, demonstrations and frames of `refs`, and the frames the visual PCA is fitted on (every
    `frame_stride`-th of each demonstration)."""
    return {
        "num_files": len({ref.file for ref in refs}),
        "num_demos": len(refs),
        "num_frames": sum(ref.num_frames for ref in refs),
        "num_frames_fitted": sum(len(range(0, ref.num_frames, frame_stride)) for ref in refs),
    }


def fitted_artefact(
    vision: VisionEncoder,
    language: LanguageEncoder,
    instructions: list[str],
    features: dict[str, list[torch.Tensor]],
    language_dim: int,
    vision_dim_per_camera: int,
    preprocessing: PreprocessingSpec,
    start: float,
    fit: dict,
) -> FrontendArtefact:
    """The PCA bases and the encoders' identities of a fit, whatever its input (LIBERO hdf5 or a LeRobot dataset).

    The language basis is fitted on one embedding per entry of `instructions`, each camera's visual basis on its
    encoded frames `features`. `fit` describes the input; the seconds since `start` and the library versions are
    added to it.
    """
    return FrontendArtefact(
        language=fit_pca(language(instructions), language_dim),
        cameras={camera: fit_pca(torch.cat(f).numpy(), vision_dim_per_camera) for camera, f in features.items()},
        vision_weights=vision.weights,
        vision_fingerprint=vision.fingerprint,
        vision_precision=vision.precision,
        language_source=language.source,
        language_fingerprint=language.fingerprint,
        preprocessing=preprocessing,
        fit={
            **fit,
            "seconds": round(time.perf_counter() - start, 1),
            "versions": package_versions(FRONTEND_DISTRIBUTIONS),
        },
    )


def variance_summary(artefact: FrontendArtefact) -> str:
    """One line saying how much of each PCA basis carries variance."""
    parts = [f"language {artefact.language.components_with_variance}/{artefact.language_dim}"]
    for camera, basis in artefact.cameras.items():
        kept = float(np.sum(basis.explained_variance_ratio))
        parts.append(f"{camera} {basis.components_with_variance}/{basis.n_components} ({kept:.1%} of variance)")
    return "components carrying variance: " + ", ".join(parts)
