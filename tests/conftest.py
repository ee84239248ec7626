"""Shared fixtures: a tiny generated LeRobot dataset with PredVLA's cached columns."""

import os
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from lerobot_predvla.data.synthetic import make_synthetic_dataset  # noqa: E402


@pytest.fixture(scope="session")
def synthetic_dataset(tmp_path_factory) -> Path:
    """Root of a 2-task, 8-episode dataset (episodes of 20-30 steps)."""
    root = tmp_path_factory.mktemp("data") / "synthetic"
    make_synthetic_dataset(root, num_tasks=2, episodes_per_task=4, min_length=20, max_length=30, seed=0)
    return root
