"""Fitting the front end's PCA bases on an existing LeRobot dataset (`predvla fit-frontend --dataset-root`).

The same encoders and PCA as on LIBERO hdf5 (Section 4.1): every chosen camera gets its own visual basis
(512 -> vision_dim_per_camera) fitted on the dataset's frames, and the language basis (384 ->
language_dim) is fitted on one instruction embedding per episode and task.
"""

import time
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_predvla.data.fitting import fitted_artefact
from lerobot_predvla.data.lerobot_source import SOURCE_ORIENTATION, LeRobotSource
from lerobot_predvla.frontend.artefact import FrontendArtefact
from lerobot_predvla.frontend.language import LanguageEncoder
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec, preprocess_images
from lerobot_predvla.frontend.vision import VisionEncoder, VisionWeights


@dataclass
class FitDatasetFrontendConfig:
    """Settings of `predvla fit-frontend --dataset-root/--dataset-repo-id`.

    Args:
        vision_weights: ResNet18 weights.
        dataset_root: Local root of a LeRobot v3 dataset.
        dataset_repo_id: Hub repo id of the dataset (loaded through LeRobot; with `dataset_root`, the id
            recorded for the local copy).
        cameras: Camera keys to encode, in concatenation order; None: every camera of the dataset.
        language_dim: Language PCA components (Table 1: 64).
        vision_dim_per_camera: Visual PCA components per camera (Table 1: 96).
        precision: Precision of the ResNet18 features, "fp32" or "bf16"; recorded and reused.
        image_size: Square side the images are resized to before ResNet18.
        frame_stride: Use every n-th frame of each episode for the visual PCA (1 = all frames).
        batch_size: Images per ResNet18 forward pass.
    """

    vision_weights: VisionWeights
    dataset_root: Path | None = None
    dataset_repo_id: str | None = None
    cameras: list[str] | None = None
    language_dim: int = 64
    vision_dim_per_camera: int = 96
    precision: str = "fp32"
    image_size: int = PreprocessingSpec.image_size
    frame_stride: int = 1
    batch_size: int = 64


def fit_frontend_on_dataset(cfg: FitDatasetFrontendConfig) -> FrontendArtefact:
    """Encode the dataset's frames and instructions with the frozen encoders and fit the PCA bases."""
    if cfg.frame_stride < 1:
        raise ValueError(f"--frame-stride must be >= 1, got {cfg.frame_stride}.")
    start = time.perf_counter()
    source = LeRobotSource.open(cfg.dataset_root, cfg.dataset_repo_id, cfg.cameras)
    preprocessing = PreprocessingSpec(image_size=cfg.image_size, orientation=SOURCE_ORIENTATION)
    vision = VisionEncoder(cfg.vision_weights, cfg.precision, batch_size=cfg.batch_size)
    language = LanguageEncoder()

    features: dict[str, list[torch.Tensor]] = {camera: [] for camera in source.cameras}
    total = sum(len(range(0, int(ep["length"]), cfg.frame_stride)) for ep in source.meta.episodes)
    with tqdm(total=total, desc="encoding frames", unit="frame") as progress:
        for batch in source.frame_batches(cfg.batch_size, cfg.frame_stride):
            for camera, images in batch.images.items():
                features[camera].append(vision(preprocess_images(images, preprocessing)))
            progress.update(len(batch.index))

    instructions = source.episode_tasks()
    return fitted_artefact(
        vision, language, instructions, features, cfg.language_dim, cfg.vision_dim_per_camera, preprocessing, start,
        fit={
            "dataset": source.name,
            "dataset_repo_id": source.dataset.repo_id,
            "cameras": source.cameras,
            "num_demos": source.num_episodes,
            "num_frames": source.num_frames,
            "frame_stride": cfg.frame_stride,
            "num_distinct_instructions": len(set(instructions)),
        },
    )
