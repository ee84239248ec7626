"""Front-end throughput on a video-encoded LeRobot dataset: `predvla fit-frontend --dataset-root` and
`predvla convert --dataset-root`, end to end (start-up, decoding, ResNet18, PCA, writing the new dataset), in
frames per second (one frame: every camera).

The dataset is generated offline with LeRobot's own `LeRobotDataset.create(use_videos=True)` (two cameras, LeRobot's
default video codec), then fitted and converted with random ResNet18 weights (the same computation as ImageNet's).

    python -m benchmarks.bench_frontend_dataset --episodes 100 --length 200   # 20,000 frames
"""

import argparse
import itertools
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_predvla.columns import ACTION_DIM, HDF5_CAMERAS, LEROBOT_LIBERO_STATE_DIM
from lerobot_predvla.data.dataset_conversion import convert_dataset
from lerobot_predvla.data.dataset_fitting import FitDatasetFrontendConfig, fit_frontend_on_dataset
from lerobot_predvla.data.lerobot_source import LeRobotSource
from lerobot_predvla.frontend.vision import PRECISIONS, VisionWeights

CAMERAS = tuple(HDF5_CAMERAS)  # LIBERO's community layout: its two cameras, its 8-dim state
STATE_DIM, FPS = LEROBOT_LIBERO_STATE_DIM, 10


def make_video_dataset(root: Path, episodes: int, length: int, size: int = 128, seed: int = 0) -> Path:
    """`episodes` x `length` frames of two `size` px cameras (a gradient with a moving square), video-encoded."""
    rng = np.random.default_rng(seed)
    image = {"dtype": "video", "shape": (size, size, 3), "names": ["height", "width", "channels"]}
    features = {key: image for key in CAMERAS}
    features["observation.state"] = {"dtype": "float32", "shape": (STATE_DIM,), "names": None}
    features["action"] = {"dtype": "float32", "shape": (ACTION_DIM,), "names": None}
    dataset = LeRobotDataset.create("local/frontend_bench", FPS, features, root=root, use_videos=True)
    yy, xx = np.mgrid[0:size, 0:size] / size
    side = size // 4
    for episode in range(episodes):
        base = np.stack([xx, yy, 1 - xx * yy], -1) * rng.uniform(60, 200, 3)
        for _ in range(length):
            frame = {}
            for key in CAMERAS:
                pixels = base.copy()
                y, x = rng.integers(0, size - side, 2)
                pixels[y : y + side, x : x + side] = rng.uniform(0, 255, 3)
                frame[key] = pixels.astype(np.uint8)
            frame["observation.state"] = rng.standard_normal(STATE_DIM).astype(np.float32)
            frame["action"] = rng.uniform(-1, 1, ACTION_DIM).astype(np.float32)
            dataset.add_frame({**frame, "task": f"task {episode % 10}"})
        dataset.save_episode()
    dataset.finalize()
    return root


def frontend_throughput(workdir: Path, dataset_root: Path, precision: str, batch_size: int = 64) -> dict:
    """Fit a front end on the dataset and convert it; seconds and frames per second of each (a previous run's
    outputs in `workdir` are replaced)."""
    for previous in (workdir / f"frontend_{precision}", workdir / f"converted_{precision}"):
        shutil.rmtree(previous, ignore_errors=True)
    frames = LeRobotDataset("local/frontend_bench", root=dataset_root).meta.total_frames
    start = time.perf_counter()
    artefact = fit_frontend_on_dataset(FitDatasetFrontendConfig(
        vision_weights=VisionWeights.parse("random"), dataset_root=dataset_root, precision=precision,
        batch_size=batch_size,
    ))
    fit_s = time.perf_counter() - start
    artefact.save(workdir / f"frontend_{precision}")
    summary = convert_dataset(workdir / f"frontend_{precision}", workdir / f"converted_{precision}",
                              dataset_root=dataset_root, batch_size=batch_size)
    return {"frames": frames, "precision": precision, "fit_s": fit_s, "fit_frames_per_s": frames / fit_s,
            "convert_s": summary.seconds, "convert_frames_per_s": frames / summary.seconds}


def decoding_rates(dataset_root: Path, frames: int = 100, batch_size: int = 50, repeats: int = 3) -> dict:
    """Frames/s of the first `frames` frames (every camera) read one by one through `LeRobotDataset.__getitem__`
    and a batch at a time through `LeRobotSource.frame_batches`, in alternation; and whether they are identical."""
    source = LeRobotSource.open(dataset_root)

    def one_by_one() -> dict[str, torch.Tensor]:
        items = [source.dataset[i] for i in range(frames)]
        return {key: torch.stack([item[key] for item in items]) for key in source.cameras}

    def batched() -> dict[str, torch.Tensor]:
        batches = list(itertools.islice(source.frame_batches(batch_size), -(-frames // batch_size)))
        return {key: torch.cat([b.images[key] for b in batches])[:frames] for key in source.cameras}

    reference, candidate = one_by_one(), batched()
    rates: dict[str, list[float]] = {"one_by_one": [], "batched": []}
    for _ in range(repeats):
        for name, read in (("one_by_one", one_by_one), ("batched", batched)):
            start = time.perf_counter()
            read()
            rates[name].append(frames / (time.perf_counter() - start))
    return {"identical": all(torch.equal(reference[k], candidate[k]) for k in reference),
            **{f"decode_frames_per_s_{name}": statistics.median(values) for name, values in rates.items()}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--length", type=int, default=200)
    parser.add_argument("--size", type=int, default=128, help="camera side in pixels")
    parser.add_argument("--precision", choices=PRECISIONS, nargs="+", default=list(PRECISIONS))
    parser.add_argument("--workdir", type=Path, default=None, help="keep the dataset here (default: a temp dir)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        workdir = args.workdir or Path(tmp)
        dataset_root = workdir / "video_dataset"
        if not dataset_root.exists():
            start = time.perf_counter()
            make_video_dataset(dataset_root, args.episodes, args.length, args.size)
            print(f"made {args.episodes * args.length} frames x {len(CAMERAS)} cameras in "
                  f"{time.perf_counter() - start:.0f} s")
        print(json.dumps({k: round(v, 1) if isinstance(v, float) else v
                          for k, v in decoding_rates(dataset_root).items()}))
        for precision in args.precision:
            print(json.dumps({k: round(v, 2) if isinstance(v, float) else v
                              for k, v in frontend_throughput(workdir, dataset_root, precision).items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
