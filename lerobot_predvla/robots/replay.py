"""The dataset-replay robot and camera: one recorded episode played as live observations, actions recorded.

Frames are served as LeRobot's cameras deliver them (uint8 (H, W, 3)) and the joint state as LeRobot's arms
report it (`{motor: float}`), in the dataset's motor order. The robot and each of its cameras advance one frame
per `get_observation()`, so they stay in step; at the end of the episode they start again from its first frame.
"""

import json
import logging
import sys
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import torch
from lerobot.cameras import Camera
from lerobot.cameras.utils import make_cameras_from_configs
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.robots import Robot
from lerobot.utils.constants import OBS_STATE

from lerobot_predvla.robots.config_replay import (
    REPLAY_TYPE,
    DatasetReplayCameraConfig,
    DatasetReplayRobotConfig,
    RecordedLayout,
)

# lerobot-rollout's function that sends the policy's action of a tick (lerobot/rollout/strategies/core.py, 0.6.1).
POLICY_STEP = "send_next_action"


class RecordedEpisode:
    """Frames of one episode of a LeRobot dataset, as `LeRobotDataset` serves them, by position in the episode."""

    def __init__(self, root: str, episode: int):
        root_path = Path(root).expanduser().resolve()
        self.dataset = LeRobotDataset(f"local/{root_path.name}", root=root_path)
        bounds = self.dataset.meta.episodes[episode]
        self.start, self.stop = int(bounds["dataset_from_index"]), int(bounds["dataset_to_index"])
        self._cached: tuple[int, dict] | None = None

    def __len__(self) -> int:
        return self.stop - self.start

    def frame(self, position: int) -> dict:
        """Frame `position mod len(self)` of the episode (the last one is kept: robot and cameras share it)."""
        index = self.start + position % len(self)
        if self._cached is None or self._cached[0] != index:
            self._cached = (index, self.dataset[index])
        return self._cached[1]


@lru_cache(maxsize=8)
def recorded_episode(root: str, episode: int) -> RecordedEpisode:
    """One reader per (dataset, episode), shared by the robot and its cameras."""
    return RecordedEpisode(root, episode)


def action_source(depth: int = 12) -> str:
    """"policy" when the action comes from lerobot-rollout's policy step (`send_next_action`), else "lerobot": the
    moves LeRobot makes by itself (interpolating back to the start pose between episodes and at the end)."""
    frame = sys._getframe(2)
    for _ in range(depth):
        if frame is None:
            break
        if frame.f_code.co_name == POLICY_STEP:
            return "policy"
        frame = frame.f_back
    return "lerobot"


def as_camera_frame(image: torch.Tensor) -> np.ndarray:
    """LeRobotDataset's float (3, H, W) image in [0, 1] as a camera delivers it: uint8 (H, W, 3)."""
    return np.round(image.permute(1, 2, 0).numpy() * 255).astype(np.uint8)


class DatasetReplayCamera(Camera):
    """`type: predvla_replay` camera: one image stream of a recorded episode (see `DatasetReplayCameraConfig`)."""

    def __init__(self, config: DatasetReplayCameraConfig):
        super().__init__(config)
        self.config = config
        self.position = 0
        self._episode: RecordedEpisode | None = None
        self._latest: np.ndarray | None = None

    @property
    def is_connected(self) -> bool:
        return self._episode is not None

    @staticmethod
    def find_cameras() -> list[dict[str, Any]]:
        return []  # nothing to discover: replay cameras are configured by dataset and key

    def connect(self, warmup: bool = True) -> None:
        self._episode = recorded_episode(self.config.dataset_root, self.config.episode)

    def read(self) -> np.ndarray:
        if self._episode is None:
            raise ConnectionError(f"{self}: read() before connect().")
        self._latest = as_camera_frame(self._episode.frame(self.position)[self.config.key])
        self.position += 1
        return self._latest

    def async_read(self, timeout_ms: float = 200) -> np.ndarray:
        return self.read()

    def read_latest(self, max_age_ms: int = 500) -> np.ndarray:
        return self.read() if self._latest is None else self._latest

    def disconnect(self) -> None:
        self._episode = None

    def __str__(self) -> str:
        return f"DatasetReplayCamera({self.config.key} of {self.config.dataset_root}, episode {self.config.episode})"


class DatasetReplayRobot(Robot):
    """`--robot.type=predvla_replay`: a recorded episode's observations, actions recorded (no hardware).

    `actions` holds every action sent, in order; `send_action` rejects an action whose motors are not the
    dataset's, as an arm's bus would.
    """

    config_class = DatasetReplayRobotConfig
    name = REPLAY_TYPE

    def __init__(self, config: DatasetReplayRobotConfig):
        super().__init__(config)
        self.config = config
        self.layout = RecordedLayout.read(config.dataset_root)
        self.cameras = make_cameras_from_configs(config.cameras)
        self.position = 0
        self.actions: list[dict[str, float]] = []
        self._episode: RecordedEpisode | None = None

    @property
    def observation_features(self) -> dict:
        motors = dict.fromkeys(self.layout.state_names, float)
        cameras = {name: (cam.height, cam.width, 3) for name, cam in self.config.cameras.items()}
        return {**motors, **cameras}

    @property
    def action_features(self) -> dict:
        return dict.fromkeys(self.layout.action_names, float)

    @property
    def is_connected(self) -> bool:
        return self._episode is not None

    @property
    def is_calibrated(self) -> bool:
        return True

    def connect(self, calibrate: bool = True) -> None:
        self._episode = recorded_episode(self.config.dataset_root, self.config.episode)
        for camera in self.cameras.values():
            camera.connect()
        logging.info("%s: playing episode %d of %s (%d frames, cameras %s)", self.name, self.config.episode,
                     self.config.dataset_root, len(self._episode), list(self.cameras))

    def calibrate(self) -> None:
        """Nothing to calibrate."""

    def configure(self) -> None:
        """Nothing to configure."""

    def get_observation(self) -> dict[str, Any]:
        if self._episode is None:
            raise ConnectionError(f"{self.name}: get_observation() before connect().")
        state = self._episode.frame(self.position)[OBS_STATE].tolist()
        self.position += 1
        observation: dict[str, Any] = dict(zip(self.layout.state_names, state, strict=True))
        for name, camera in self.cameras.items():
            observation[name] = camera.read()
        return observation

    def send_action(self, action: dict[str, Any]) -> dict[str, Any]:
        if self._episode is None:
            raise ConnectionError(f"{self.name}: send_action() before connect().")
        expected = set(self.layout.action_names)
        if set(action) != expected:
            raise ValueError(
                f"{self.name}: the action has the motors {sorted(action)}, the robot has {sorted(expected)} "
                f"(missing {sorted(expected - set(action))}, unknown {sorted(set(action) - expected)})."
            )
        sent = {name: float(action[name]) for name in self.layout.action_names}
        self.actions.append(sent)
        if self.config.action_log is not None:
            entry = {"tick": self.position - 1, "source": action_source(), "action": sent}
            with open(self.config.action_log, "a") as log:
                log.write(json.dumps(entry) + "\n")
        return sent

    def disconnect(self) -> None:
        for camera in self.cameras.values():
            camera.disconnect()
        self._episode = None
