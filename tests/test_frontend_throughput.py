"""The front end on a video-encoded LeRobot dataset: frames decoded a batch at a time (in a background thread) are
the frames `LeRobotDataset.__getitem__` serves one by one, and `predvla convert --dataset-root` gives the features
of the frame-by-frame reference (fp32 exactly up to convolution rounding; bf16 within its rounding)."""

from dataclasses import replace

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot_factory import LIBERO_COMMUNITY, make_dataset

from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.data.dataset_conversion import convert_dataset
from lerobot_predvla.data.dataset_fitting import FitDatasetFrontendConfig, fit_frontend_on_dataset
from lerobot_predvla.data.lerobot_source import LeRobotSource
from lerobot_predvla.frontend import FrozenFrontend
from lerobot_predvla.frontend.vision import VisionWeights

EPISODES = [("pick up the alphabet soup and place it in the basket", 7), ("pick up the milk", 6)]
# Largest |difference| of a cached feature from the fp32 frame-by-frame reference (features are PCA scores of
# order 1-10): fp32 batched convolutions round differently from one-image ones; bf16 keeps 8 mantissa bits.
TOLERANCE = {"fp32": 1e-4, "bf16": 0.25}


@pytest.fixture(scope="module")
def video_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("video") / "source"
    make_dataset(root, LIBERO_COMMUNITY, EPISODES, repo_id="local/video", use_videos=True)
    return root


@pytest.mark.parametrize("stride", [1, 2])
def test_batched_decoding_serves_lerobots_own_frames(video_dataset, stride):
    source = LeRobotSource.open(video_dataset)
    dataset = LeRobotDataset("local/video", root=video_dataset)
    batches = list(source.frame_batches(batch_size=3, frame_stride=stride))
    served = [int(i) for batch in batches for i in batch.index]
    assert served == [i for start, n in ((0, 7), (7, 6)) for i in range(start, start + n, stride)]
    for batch in batches:
        reference = [dataset[int(i)] for i in batch.index]
        assert batch.tasks == [item["task"] for item in reference]
        assert all(episode == batch.episode for episode in (int(item["episode_index"]) for item in reference))
        for camera in source.cameras:
            assert torch.equal(batch.images[camera], torch.stack([item[camera] for item in reference]))


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_conversion_matches_the_frame_by_frame_reference(video_dataset, tmp_path, precision):
    artefact = fit_frontend_on_dataset(FitDatasetFrontendConfig(
        vision_weights=VisionWeights.parse("random"), dataset_root=video_dataset, precision=precision,
        image_size=64, language_dim=2, vision_dim_per_camera=8,
    ))
    artefact.save(tmp_path / "frontend")
    convert_dataset(tmp_path / "frontend", tmp_path / "converted", dataset_root=video_dataset, language_dim=2,
                    vision_dim_per_camera=8, batch_size=4)
    original = LeRobotDataset("local/video", root=video_dataset)
    converted = LeRobotDataset("local/converted", root=tmp_path / "converted")
    reference = FrozenFrontend(replace(artefact, vision_precision="fp32"), batch_size=1, verbose=False)
    cameras = list(artefact.cameras)
    for i in range(len(original)):
        frame = original[i]
        expected = reference.encode_images({camera: frame[camera][None] for camera in cameras})[0]
        cached = converted[i][OBS_VISION_FEATURES]
        assert (cached - expected).abs().max() <= TOLERANCE[precision], i
