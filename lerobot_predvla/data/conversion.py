"""LIBERO hdf5 -> LeRobot v3.0 dataset with PredVLA's cached front-end features (`predvla convert`).

The dataset is written into a temporary directory beside `out` and renamed into place only once it is
complete, so a failed conversion leaves nothing behind. States and actions are checked finite before any
work starts, the encoded features before they are written (`finite.check_finite`).

With an oracle (`predvla convert --oracle`, a diagnostic) the visual features are the simulator's standardised
object poses relative to the gripper (`frontend.oracle`), given per demonstration, and no camera is written.
"""

import dataclasses
import shutil
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.constants import ACTION, OBS_STATE
from tqdm import tqdm

from lerobot_predvla.columns import FRONTEND_META_DIR, HDF5_CAMERAS, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.data.libero_hdf5 import DemoRef, read_demo, scan_suites
from lerobot_predvla.frontend.frozen import FrozenFrontend
from lerobot_predvla.frontend.oracle import OracleStandardisation
from lerobot_predvla.frontend.preprocessing import libero_hdf5_to_lerobot
from lerobot_predvla.utils.finite import check_finite

# Per demonstration (file, demo name): its oracle features (N, dim), already standardised.
OracleFeatures = Mapping[tuple[Path, str], np.ndarray]

LIBERO_FPS = 20
IMAGE_STORAGES = ("video", "png", "none")  # "none": the cached features only, as `predvla features-only` keeps
STATE_NAMES = [*(f"joint_{i}" for i in range(7)), "gripper_0", "gripper_1"]
ACTION_NAMES = ["x", "y", "z", "roll", "pitch", "yaw", "gripper"]


@dataclass
class ConversionSummary:
    """What `convert_suite` wrote."""

    root: Path
    episodes: int
    frames: int
    tasks: int
    seconds: float

    def __str__(self) -> str:
        return (
            f"wrote {self.root}: {self.episodes} episodes, {self.frames} frames, {self.tasks} tasks in "
            f"{self.seconds:.1f} s ({self.frames / max(self.seconds, 1e-9):.1f} frames/s)"
        )


def dataset_features(image_shapes: tuple, vision_dim: int, language_dim: int, image_storage: str) -> dict:
    """LeRobot feature specification of a converted suite (no camera for empty `image_shapes`)."""
    dtype = "video" if image_storage == "video" else "image"
    features = {
        camera: {"dtype": dtype, "shape": shape, "names": ["height", "width", "channels"]}
        for camera, shape in zip(HDF5_CAMERAS, image_shapes, strict=True)
    } if image_shapes else {}
    features[OBS_STATE] = {"dtype": "float32", "shape": (len(STATE_NAMES),), "names": STATE_NAMES}
    features[ACTION] = {"dtype": "float32", "shape": (len(ACTION_NAMES),), "names": ACTION_NAMES}
    features[OBS_VISION_FEATURES] = {"dtype": "float32", "shape": (vision_dim,), "names": None}
    features[OBS_LANGUAGE_FEATURES] = {"dtype": "float32", "shape": (language_dim,), "names": None}
    return features


def _write_episodes(
    dataset: LeRobotDataset, refs: list[DemoRef], frontend: FrozenFrontend, oracle: OracleFeatures | None,
    write_images: bool,
) -> None:
    instructions = sorted({ref.instruction for ref in refs})
    language = dict(zip(instructions, frontend.encode_instructions(instructions).numpy(), strict=True))
    for text, features in language.items():
        check_finite(features, f"instruction {text!r}", OBS_LANGUAGE_FEATURES)
    with tqdm(total=sum(ref.num_frames for ref in refs), desc="converting", unit="frame") as progress:
        for ref in refs:
            demo = read_demo(ref, cameras=oracle is None)
            images = {camera: libero_hdf5_to_lerobot(pixels) for camera, pixels in demo.images.items()}
            vision = _encode_vision(frontend, images) if oracle is None else oracle[(ref.file, ref.demo)]
            check_finite(vision, f"{ref.file}, demo '{ref.demo}'", OBS_VISION_FEATURES)
            for t in range(ref.num_frames):
                frame = {camera: pixels[t] for camera, pixels in images.items()} if write_images else {}
                frame[OBS_STATE] = demo.state[t]
                frame[ACTION] = demo.action[t]
                frame[OBS_VISION_FEATURES] = vision[t]
                frame[OBS_LANGUAGE_FEATURES] = language[ref.instruction]
                frame["task"] = ref.instruction
                dataset.add_frame(frame)
            dataset.save_episode(parallel_encoding=False)
            progress.update(ref.num_frames)


def _encode_vision(frontend: FrozenFrontend, images: dict[str, np.ndarray]) -> np.ndarray:
    """Visual features of every frame, each distinct frame encoded once: demos rendered every k-th step (`predvla
    demos --render-interval k`) repeat their images in between."""
    num_frames = len(next(iter(images.values())))
    repeated = np.ones(num_frames, dtype=bool)
    repeated[0] = False
    for pixels in images.values():
        repeated[1:] &= (pixels[1:] == pixels[:-1]).all(axis=(1, 2, 3))
    distinct = np.flatnonzero(~repeated)
    vision = frontend.encode_images({c: pixels[distinct] for c, pixels in images.items()}).numpy()
    return vision[np.cumsum(~repeated) - 1]


def convert_suite(
    hdf5_root: Path | str,
    suite: str,
    frontend_dir: Path | str,
    out: Path | str,
    repo_id: str | None = None,
    language_dim: int = 64,
    vision_dim_per_camera: int = 96,
    image_storage: str = "video",
    batch_size: int = 64,
    oracle: tuple[OracleStandardisation, OracleFeatures] | None = None,
) -> ConversionSummary:
    """Convert one LIBERO suite into a LeRobot dataset rooted at `out` (which must not exist).

    Args:
        hdf5_root: Directory holding `<suite>/<task>_demo.hdf5`.
        suite: Suite name, e.g. "libero_object".
        frontend_dir: Artefact written by `predvla fit-frontend`.
        out: Dataset root directory to create.
        repo_id: Dataset repo id (default `local/<suite>`).
        language_dim: Required language feature size (checked against the artefact).
        vision_dim_per_camera: Required visual feature size per camera (checked against the artefact).
        image_storage: "video" (LeRobot's default, AV1 MP4, lossy, small), "png" (lossless, ~5x larger) or "none"
            (no camera column: what every policy of this plugin trains on, the same columns and values as
            `predvla features-only` makes from a converted dataset, without encoding a video).
        batch_size: Images per ResNet18 forward pass.
        oracle: The oracle front end's standardisation and every demonstration's features (`libero.oracle.
            fit_oracle`): they replace the visual features, the dataset gets no camera, and the artefact saved
            with it records the standardisation. None (default): the cameras through ResNet18 and PCA.
    """
    if image_storage not in IMAGE_STORAGES:
        raise ValueError(f"image_storage must be one of {IMAGE_STORAGES}, got {image_storage!r}.")
    start = time.perf_counter()
    out = Path(out).expanduser().resolve()
    if out.exists():
        raise FileExistsError(f"{out} already exists; choose a new --out or remove it.")
    refs = scan_suites(hdf5_root, [suite])  # Validates every file before anything is written.
    frontend = FrozenFrontend.load(frontend_dir, batch_size=batch_size)
    frontend.artefact.check_dims(language_dim, vision_dim_per_camera, list(HDF5_CAMERAS), frontend_dir)
    artefact = frontend.artefact if oracle is None else dataclasses.replace(frontend.artefact, oracle=oracle[0])

    out.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        dataset = LeRobotDataset.create(
            repo_id=repo_id or f"local/{suite}",
            fps=LIBERO_FPS,
            features=dataset_features(
                refs[0].image_shapes if oracle is None and image_storage != "none" else (), artefact.vision_dim,
                artefact.language_dim,
                image_storage,
            ),
            root=staging / out.name,
            robot_type="panda",
            use_videos=image_storage == "video",
        )
        try:
            _write_episodes(dataset, refs, frontend, None if oracle is None else oracle[1],
                            write_images=oracle is None and image_storage != "none")
        finally:
            dataset.finalize()
        artefact.save(staging / out.name / FRONTEND_META_DIR)
        (staging / out.name).rename(out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return ConversionSummary(
        root=out,
        episodes=len(refs),
        frames=sum(ref.num_frames for ref in refs),
        tasks=len({ref.instruction for ref in refs}),
        seconds=time.perf_counter() - start,
    )
