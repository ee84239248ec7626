"""Existing LeRobot dataset -> the same dataset plus PredVLA's cached columns (`predvla convert --dataset-root`).

Every original column, video and metadata file is kept as it is (LeRobot's own `add_features` copies them);
`observation.vision_features` (vision_dim_per_camera per camera, in the front end's camera order) and
`observation.language_features` (language_dim) are added, with their statistics, and the front-end artefact
travels with the dataset (`meta/predvla_frontend`). The dataset is written into a temporary directory beside
`out` and renamed into place only once it is complete, so a failed conversion leaves nothing behind.
"""

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from lerobot.datasets.compute_stats import get_feature_stats
from lerobot.datasets.dataset_tools import add_features
from lerobot.datasets.io_utils import load_stats, write_stats
from tqdm import tqdm

from lerobot_predvla.columns import FRONTEND_META_DIR, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.data.conversion import ConversionSummary
from lerobot_predvla.data.lerobot_source import LeRobotSource
from lerobot_predvla.frontend.artefact import FrontendArtefactError
from lerobot_predvla.frontend.frozen import FrozenFrontend


def encode_dataset(source: LeRobotSource, frontend: FrozenFrontend, batch_size: int) -> dict[str, np.ndarray]:
    """Cached features of every frame, rows in the dataset's `index` order."""
    vision = np.zeros((source.num_frames, frontend.artefact.vision_dim), dtype=np.float32)
    language = np.zeros((source.num_frames, frontend.artefact.language_dim), dtype=np.float32)
    tasks = sorted(set(source.task_strings().values()))
    rows = dict(zip(tasks, frontend.encode_instructions(tasks).numpy(), strict=True))
    with tqdm(total=source.num_frames, desc="converting", unit="frame") as progress:
        for batch in source.frame_batches(batch_size):
            vision[batch.index] = frontend.encode_images(batch.images).numpy()
            language[batch.index] = np.stack([rows[task] for task in batch.tasks])
            progress.update(len(batch.index))
    return {OBS_VISION_FEATURES: vision, OBS_LANGUAGE_FEATURES: language}


def parquet_row_order(root: Path) -> np.ndarray:
    """The `index` of each data row in the order LeRobot's `add_features` walks them (sorted files, rows)."""
    files = sorted((root / "data").glob("*/*.parquet"))
    return np.concatenate([pq.read_table(f, columns=["index"]).column("index").to_numpy() for f in files])


def convert_dataset(
    frontend_dir: Path | str,
    out: Path | str,
    dataset_root: Path | str | None = None,
    dataset_repo_id: str | None = None,
    repo_id: str | None = None,
    cameras: list[str] | None = None,
    language_dim: int = 64,
    vision_dim_per_camera: int = 96,
    batch_size: int = 64,
) -> ConversionSummary:
    """Write `out` (which must not exist): the source dataset plus PredVLA's cached feature columns.

    Args:
        frontend_dir: Artefact written by `predvla fit-frontend`.
        out: Dataset root directory to create.
        dataset_root: Local root of the source LeRobot v3 dataset.
        dataset_repo_id: Hub repo id of the source (loaded through LeRobot; with `dataset_root`, the id of
            the local copy).
        repo_id: Repo id of the new dataset (default `local/<out name>`).
        cameras: Cameras to encode, in order; None: the cameras the front end was fitted on.
        language_dim: Required language feature size (checked against the artefact).
        vision_dim_per_camera: Required visual feature size per camera (checked against the artefact).
        batch_size: Images per ResNet18 forward pass.
    """
    start = time.perf_counter()
    out = Path(out).expanduser().resolve()
    if out.exists():
        raise FileExistsError(f"{out} already exists; choose a new --out or remove it.")
    frontend = FrozenFrontend.load(frontend_dir, batch_size=batch_size)
    fitted = list(frontend.artefact.cameras)
    source = LeRobotSource.open(dataset_root, dataset_repo_id, cameras if cameras is not None else fitted)
    if source.cameras != fitted:
        raise FrontendArtefactError(
            f"{frontend_dir}: the front end was fitted on cameras {fitted}, --cameras asks for {source.cameras}; "
            "fit a front end on these cameras (`predvla fit-frontend --cameras ...`)."
        )
    frontend.artefact.check_dims(language_dim, vision_dim_per_camera, source.cameras, frontend_dir)
    columns = encode_dataset(source, frontend, batch_size)

    order = parquet_row_order(source.dataset.root)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        features = {
            key: (values[order], {"dtype": "float32", "shape": (values.shape[1],), "names": None})
            for key, values in columns.items()
        }
        written = add_features(source.dataset, features, output_dir=staging / out.name,
                               repo_id=repo_id or f"local/{out.name}")
        stats = load_stats(written.root) or {}
        for key, values in columns.items():
            stats[key] = get_feature_stats(values, axis=0, keepdims=False)
        write_stats(stats, written.root)
        frontend.artefact.save(written.root / FRONTEND_META_DIR)
        written.root.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ConversionSummary(
        root=out,
        episodes=source.num_episodes,
        frames=source.num_frames,
        tasks=len(source.task_strings()),
        seconds=time.perf_counter() - start,
    )
