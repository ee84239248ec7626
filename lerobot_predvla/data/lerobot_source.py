"""Reader and validator of an existing LeRobot v3 dataset as the front end's input (`--dataset-root`).

`LeRobotSource.open` loads the dataset with LeRobot's own `LeRobotDataset` (from a local root, or by repo id
through LeRobot's Hub download) and validates everything the front end needs before any work starts: the
camera features, a non-empty task string for every frame, and episode lengths that agree between the
episode index, the data rows and the videos. Every problem is a `LeRobotSourceError` naming the dataset,
the episode and the key. Frames are served exactly as `LeRobotDataset` serves them to training and as
LeRobot's robot and environment loops deliver them: float (3, H, W) images in [0, 1], in the dataset's
own orientation (no rotation is applied).
"""

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.video_utils import decode_video_frames
from lerobot.utils.constants import ACTION, OBS_STATE
from lerobot.utils.import_utils import get_safe_default_video_backend

from lerobot_predvla.columns import OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES

INFO_FILE = "meta/info.json"
SOURCE_ORIENTATION = "as stored in the LeRobot dataset (no rotation)"


class LeRobotSourceError(ValueError):
    """Invalid LeRobot dataset input, located by dataset, episode and key."""

    def __init__(self, dataset: str, message: str, episode: int | None = None, key: str | None = None):
        where = f"dataset {dataset}" + (f", episode {episode}" if episode is not None else "")
        where += f", key '{key}'" if key else ""
        super().__init__(f"{where}: {message}")


@dataclass
class FrameBatch:
    """Consecutive frames of one episode: global `index`, per-camera float (N, 3, H, W) images, tasks."""

    episode: int
    index: np.ndarray
    images: dict[str, torch.Tensor]
    tasks: list[str]


def _load(root: Path | None, repo_id: str | None) -> tuple[LeRobotDataset, str]:
    """The dataset and how errors name it; a local root is never completed from the Hub."""
    if root is not None:
        root = Path(root).expanduser().resolve()
        name = str(root)
        if not (root / INFO_FILE).is_file():
            raise LeRobotSourceError(name, "not a LeRobot dataset root (no meta/info.json)", key=INFO_FILE)
        if not any((root / "data").glob("*/*.parquet")):
            raise LeRobotSourceError(name, "has no data files (data/chunk-*/file-*.parquet)", key="data")
        try:
            return LeRobotDataset(repo_id or f"local/{root.name}", root=root), name
        except Exception as err:  # LeRobot reports unreadable files with many exception types.
            raise LeRobotSourceError(name, f"cannot be read by LeRobotDataset ({type(err).__name__}: {err})") from err
    if repo_id is None:
        raise ValueError("Give --dataset-root (a local LeRobot dataset) or --dataset-repo-id (a Hub dataset).")
    try:
        return LeRobotDataset(repo_id), repo_id
    except Exception as err:  # Offline mode, network and missing-repo errors come in many types.
        raise LeRobotSourceError(
            repo_id,
            f"cannot be loaded from the Hugging Face Hub ({type(err).__name__}: {str(err).splitlines()[0]}). "
            "Download it where the Hub is reachable (e.g. `hf download --repo-type dataset "
            f"{repo_id} --local-dir DIR`) and pass --dataset-root DIR",
        ) from err


@dataclass
class LeRobotSource:
    """A validated LeRobot dataset and the cameras the front end encodes.

    Args:
        dataset: The dataset, loaded by LeRobot.
        name: How errors and summaries name it (its root or repo id).
        cameras: Camera keys to encode, in feature-concatenation order.
    """

    dataset: LeRobotDataset
    name: str
    cameras: list[str]

    @classmethod
    def open(
        cls, root: Path | str | None = None, repo_id: str | None = None, cameras: list[str] | None = None
    ) -> "LeRobotSource":
        """Load and validate a dataset; `cameras` None means every camera feature of the dataset."""
        dataset, name = _load(Path(root) if root is not None else None, repo_id)
        source = cls(dataset, name, [])
        source.cameras = source._check_cameras(cameras)
        source._check_cached_columns()
        source._check_episodes()
        return source

    @property
    def meta(self):
        return self.dataset.meta

    @property
    def num_frames(self) -> int:
        return self.meta.total_frames

    @property
    def num_episodes(self) -> int:
        return self.meta.total_episodes

    def _check_cameras(self, requested: list[str] | None) -> list[str]:
        available = list(self.meta.camera_keys)
        if not available:
            raise LeRobotSourceError(
                self.name, "has no image or video feature: PredVLA's front end needs at least one camera",
                key="features",
            )
        cameras = available if requested is None else list(requested)
        for key in cameras:
            if key not in available:
                raise LeRobotSourceError(self.name, f"no such camera; the dataset has {available}", key=key)
            shape = tuple(self.meta.features[key]["shape"])
            if len(shape) != 3 or 3 not in (shape[0], shape[-1]):
                raise LeRobotSourceError(self.name, f"shape {shape}, expected an RGB image (H, W, 3)", key=key)
        if len(set(cameras)) != len(cameras):
            raise LeRobotSourceError(self.name, f"camera listed twice in {cameras}", key="cameras")
        return cameras

    def _check_cached_columns(self) -> None:
        for key in (OBS_VISION_FEATURES, OBS_LANGUAGE_FEATURES):
            if key in self.meta.features:
                raise LeRobotSourceError(self.name, "already has PredVLA's cached features (converted twice?)", key=key)

    def _check_episodes(self) -> None:
        """Finite state and action; tasks present and non-empty; episode index, data rows and videos of equal
        length."""
        vectors = [key for key in (OBS_STATE, ACTION) if key in self.meta.features]
        columns = self.dataset.hf_dataset.select_columns(["episode_index", "task_index", *vectors])
        columns = columns.with_format("numpy")
        episode_of_row = np.asarray(columns["episode_index"]).reshape(-1)
        task_of_row = np.asarray(columns["task_index"]).reshape(-1)
        for key in vectors:
            bad = ~np.isfinite(np.asarray(columns[key], dtype=np.float64).reshape(len(episode_of_row), -1)).all(1)
            if bad.any():
                raise LeRobotSourceError(
                    self.name, f"non-finite values in {int(bad.sum())} frames", int(episode_of_row[bad][0]), key
                )
        tasks = self.task_strings()
        rows = np.bincount(episode_of_row, minlength=self.num_episodes)
        fps = self.meta.fps
        for ep in self.meta.episodes:
            e, length = int(ep["episode_index"]), int(ep["length"])
            if rows[e] != length:
                raise LeRobotSourceError(
                    self.name, f"length mismatch: meta/episodes says {length} frames, the data has {rows[e]}",
                    e, "length",
                )
            for key in self.cameras:
                if key in self.meta.video_keys:
                    span = (ep[f"videos/{key}/to_timestamp"] - ep[f"videos/{key}/from_timestamp"]) * fps
                    if span + 0.5 < length:
                        raise LeRobotSourceError(
                            self.name, f"length mismatch: the video holds {span:.0f} frames, the episode {length}",
                            e, key,
                        )
            for t in np.unique(task_of_row[episode_of_row == e]):
                text = tasks.get(int(t))
                if text is None or not text.strip():
                    problem = "missing from meta/tasks" if text is None else "empty"
                    raise LeRobotSourceError(
                        self.name, f"task {int(t)} is {problem}: PredVLA needs an instruction per frame", e, "task"
                    )

    def task_strings(self) -> dict[int, str]:
        """task_index -> task string (meta/tasks)."""
        tasks = self.meta.tasks
        return {int(i): str(text) for text, i in zip(tasks.index, tasks["task_index"], strict=True)}

    def episode_tasks(self) -> list[str]:
        """One instruction per (episode, task) pair: each episode weighs the same in the language PCA."""
        return [str(text) for ep in self.meta.episodes for text in ep["tasks"]]

    def frame_batches(self, batch_size: int, frame_stride: int = 1) -> Iterator[FrameBatch]:
        """Every `frame_stride`-th frame of every episode, in episode order, as LeRobotDataset serves them.

        Batches are read in a background thread while the caller works on the previous one. Video cameras are
        decoded a batch at a time: one `decode_video_frames` call per camera and batch, with the timestamps,
        backend and tolerance `LeRobotDataset.__getitem__` uses for each frame, so the frames are its frames
        (one pass over the video instead of a seek from the key frame per frame)."""
        columns = self.dataset.hf_dataset.select_columns(["index", "timestamp", "task_index"]).with_format("numpy")[:]
        tasks = self.task_strings()
        chunks = [
            (int(ep["episode_index"]), indices[start : start + batch_size])
            for ep in self.meta.episodes
            for indices in [range(int(ep["dataset_from_index"]), int(ep["dataset_to_index"]), frame_stride)]
            for start in range(0, len(indices), batch_size)
        ]
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="predvla-frames") as reader:
            pending = None
            for episode, chunk in chunks:
                following = reader.submit(self._read_frames, episode, chunk, columns, tasks)
                if pending is not None:
                    yield pending.result()
                pending = following
            if pending is not None:
                yield pending.result()

    def _read_frames(
        self, episode: int, chunk: range, columns: dict[str, np.ndarray], tasks: dict[int, str]
    ) -> FrameBatch:
        rows = np.asarray(chunk)
        key = None
        try:
            images = {}
            for key in self.cameras:
                images[key] = self._decode(key, episode, rows, columns)
        except Exception as err:  # Decoding failures come in many types (av, torchcodec, PIL, ...).
            raise LeRobotSourceError(self.name, f"cannot read frames ({type(err).__name__}: {err})", episode,
                                     key) from err
        return FrameBatch(episode, columns["index"][rows].astype(np.int64),
                          images, [tasks[int(t)] for t in columns["task_index"][rows]])

    def _decode(self, key: str, episode: int, rows: np.ndarray, columns: dict[str, np.ndarray]) -> torch.Tensor:
        """Float (N, 3, H, W) images of camera `key` at data rows `rows` of one episode."""
        if key not in self.meta.video_keys:  # images stored per frame (PNG): LeRobot's own per-item path
            return torch.stack([self.dataset[int(i)][key] for i in rows])
        start = self.meta.episodes[episode][f"videos/{key}/from_timestamp"]
        return decode_video_frames(
            self.dataset.root / self.meta.get_video_file_path(episode, key),
            [start + float(t) for t in columns["timestamp"][rows]],
            self.dataset.tolerance_s,
            get_safe_default_video_backend(),
        )
