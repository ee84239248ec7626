"""The tests' tiny LeRobot datasets (lerobot_predvla/data/example_datasets.py)."""

from lerobot_predvla.data.example_datasets import LIBERO_COMMUNITY, SO101, Layout, make_dataset

__all__ = ["LIBERO_COMMUNITY", "SO101", "Layout", "make_dataset"]
