"""Tiny LeRobot v3 datasets built with LeRobot's own API, in two robots' layouts: the tests' datasets and the
recording of `predvla demo robot`.

- LIBERO community layout: 8-dim end-effector state (eef pos 3 + axis-angle 3 + gripper 2), cameras
  `observation.images.image` and `observation.images.image2`, 7-dim actions, 10 fps.
- SO-101 layout: 6-dim joint state and action, one or two cameras (`front`, `wrist`), 30 fps.

Images are small and stored as PNG (`use_videos=False`) so that they are quick to write and read;
`use_videos=True` stores them as LeRobot's default AV1 videos instead.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset


@dataclass(frozen=True)
class Layout:
    """A robot's dataset layout: cameras (key -> (H, W)), state and action names, fps, robot type."""

    cameras: dict[str, tuple[int, int]]
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]
    fps: int
    robot_type: str


LIBERO_COMMUNITY = Layout(
    cameras={"observation.images.image": (32, 32), "observation.images.image2": (32, 32)},
    state_names=("x", "y", "z", "axis_angle1", "axis_angle2", "axis_angle3", "gripper_0", "gripper_1"),
    action_names=("x", "y", "z", "roll", "pitch", "yaw", "gripper"),
    fps=10,
    robot_type="panda",
)
SO101_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
SO101 = Layout(
    cameras={"observation.images.front": (24, 32), "observation.images.wrist": (24, 32)},
    state_names=tuple(f"{j}.pos" for j in SO101_JOINTS),
    action_names=tuple(f"{j}.pos" for j in SO101_JOINTS),
    fps=30,
    robot_type="so101_follower",
)


def layout_features(layout: Layout, use_videos: bool = False) -> dict:
    features = {
        key: {"dtype": "video" if use_videos else "image", "shape": (h, w, 3), "names": ["height", "width", "channels"]}
        for key, (h, w) in layout.cameras.items()
    }
    features["observation.state"] = {
        "dtype": "float32", "shape": (len(layout.state_names),), "names": list(layout.state_names)
    }
    features["action"] = {"dtype": "float32", "shape": (len(layout.action_names),), "names": list(layout.action_names)}
    return features


def frames(shape: tuple[int, int], num_frames: int, rng: np.random.Generator) -> np.ndarray:
    """uint8 (N, H, W, 3) frames: a random colour gradient with a square moving across it."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    base = np.stack([xx / w, yy / h, 1 - xx * yy / (h * w)], axis=-1) * rng.uniform(60, 200, 3)
    out = np.repeat(base[None], num_frames, axis=0)
    side = max(2, h // 4)
    for t in range(num_frames):
        y, x = int(rng.integers(0, h - side)), int(rng.integers(0, w - side))
        out[t, y : y + side, x : x + side] = rng.uniform(0, 255, 3)
    return out.astype(np.uint8)


def make_dataset(
    root: Path, layout: Layout, episodes: list[tuple[str, int]], repo_id: str = "local/tiny", seed: int = 0,
    use_videos: bool = False,
) -> LeRobotDataset:
    """Write one episode per (task, length) with LeRobotDataset.create/add_frame/save_episode/finalize."""
    rng = np.random.default_rng(seed)
    dataset = LeRobotDataset.create(
        repo_id, layout.fps, layout_features(layout, use_videos), root=root, robot_type=layout.robot_type,
        use_videos=use_videos,
    )
    for task, length in episodes:
        images = {key: frames(shape, length, rng) for key, shape in layout.cameras.items()}
        state = np.cumsum(rng.normal(0, 0.05, (length, len(layout.state_names))), axis=0).astype(np.float32)
        action = np.clip(rng.normal(0, 0.5, (length, len(layout.action_names))), -1, 1).astype(np.float32)
        for t in range(length):
            dataset.add_frame({**{k: v[t] for k, v in images.items()}, "observation.state": state[t],
                               "action": action[t], "task": task})
        dataset.save_episode()
    dataset.finalize()
    return dataset
