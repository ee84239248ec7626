"""A converted dataset's training copy without its camera frames (`predvla features-only`).

Every policy of this plugin trains on the cached feature columns alone (Section 4.3; `sequence_table.py`), yet
LeRobot's dataset decodes every camera's frame of each index the training loop samples: about 11 ms per sample
for two 128x128 AV1 videos, a third of a baseline's update at batch 32 on one core (benchmarks/
bench_features_only.py). This copy drops the camera features with LeRobot's own `remove_feature` and keeps the
front-end artefact (`meta/predvla_frontend`), so `lerobot-train` on it draws the same samples and makes the same
updates without decoding a frame. The copy is written beside `out` and renamed into place only once complete.
"""

import shutil
import tempfile
from pathlib import Path

from lerobot.datasets.dataset_tools import remove_feature
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_predvla.columns import FRONTEND_META_DIR, OBS_VISION_FEATURES


def features_only_copy(root: Path | str, out: Path | str, repo_id: str | None = None) -> LeRobotDataset:
    """Write `out` (which must not exist): the dataset at `root` without its camera features.

    Args:
        root: Local root of a dataset written by `predvla convert` (it has `observation.vision_features`).
        out: Root of the copy to create.
        repo_id: Repo id of the copy (default `local/<out name>`).
    """
    root, out = Path(root).expanduser().resolve(), Path(out).expanduser().resolve()
    if out.exists():
        raise FileExistsError(f"{out} already exists; choose a new --out or remove it.")
    if not (root / "meta" / "info.json").is_file():
        raise FileNotFoundError(f"{root / 'meta' / 'info.json'} not found: --dataset-root must be a LeRobot dataset.")
    repo_id = repo_id or f"local/{out.name}"
    dataset = LeRobotDataset(f"local/{root.name}", root=root)
    if OBS_VISION_FEATURES not in dataset.meta.features:
        raise ValueError(
            f"{root}: the dataset has no '{OBS_VISION_FEATURES}' column, so training needs its camera frames; "
            "convert it first (`predvla convert`)."
        )
    cameras = list(dataset.meta.camera_keys)
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        target = staging / out.name
        if cameras:
            remove_feature(dataset, cameras, output_dir=target, repo_id=repo_id)
        else:
            shutil.copytree(root, target)
        if (root / FRONTEND_META_DIR).is_dir() and not (target / FRONTEND_META_DIR).is_dir():
            shutil.copytree(root / FRONTEND_META_DIR, target / FRONTEND_META_DIR)
        target.rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return LeRobotDataset(repo_id, root=out)
