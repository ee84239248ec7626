"""Configs of the dataset-replay robot and camera (`--robot.type=predvla_replay`), registered with LeRobot.

A robot that needs no hardware: it serves one recorded episode of a LeRobot dataset as its observations (the
joint state and every camera, frame by frame, from the start again at the end) and records the actions it is
sent. `lerobot-rollout` drives it exactly as an arm (`docs/robot.md`): a dry run of a checkpoint on the
observations it was trained on, before the arm moves.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

from lerobot.cameras.configs import CameraConfig
from lerobot.robots.config import RobotConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

REPLAY_TYPE = "predvla_replay"
# lerobot-rollout routes only motor features named `<motor>.pos` or `<motor>.vel` to the policy and the arm.
MOTOR_SUFFIXES = (".pos", ".vel")


@dataclass(frozen=True)
class RecordedLayout:
    """What a LeRobot dataset's `meta/info.json` says about its robot: fps, episodes, cameras, motors."""

    fps: int
    total_episodes: int
    cameras: dict[str, tuple[int, int]]  # camera name (key without `observation.images.`) -> (height, width)
    state_names: tuple[str, ...]
    action_names: tuple[str, ...]

    @classmethod
    def read(cls, root: str | Path) -> "RecordedLayout":
        info_file = Path(root).expanduser() / "meta" / "info.json"
        if not info_file.is_file():
            raise FileNotFoundError(f"--robot.dataset_root={root}: not a LeRobot dataset (no {info_file}).")
        info = json.loads(info_file.read_text())
        features = info["features"]
        for key in (OBS_STATE, ACTION):
            if key not in features or not features[key].get("names"):
                raise ValueError(f"{info_file}: the replay robot needs named '{key}' features (motor names).")
        cameras = {
            key.removeprefix(f"{OBS_IMAGES}."): tuple(ft["shape"][:2])
            for key, ft in features.items() if key.startswith(f"{OBS_IMAGES}.") and ft["dtype"] in ("image", "video")
        }
        layout = cls(int(info["fps"]), int(info["total_episodes"]), cameras, tuple(features[OBS_STATE]["names"]),
                     tuple(features[ACTION]["names"]))
        for key, names in ((OBS_STATE, layout.state_names), (ACTION, layout.action_names)):
            unrouted = [n for n in names if not n.endswith(MOTOR_SUFFIXES)]
            if unrouted:
                raise ValueError(
                    f"{info_file}: '{key}' names {unrouted} do not end in {MOTOR_SUFFIXES}; lerobot-rollout only "
                    "routes motor features named so, as LeRobot's robots record them."
                )
        return layout


@CameraConfig.register_subclass(REPLAY_TYPE)
@dataclass(kw_only=True)
class DatasetReplayCameraConfig(CameraConfig):
    """A camera that plays one camera stream of a recorded episode.

    Args:
        key: The dataset's image feature, e.g. `observation.images.front`.
        dataset_root: LeRobot dataset root; None: the robot's `dataset_root`.
        episode: Episode to play; None: the robot's `episode`.
    """

    key: str = ""
    dataset_root: str | None = None
    episode: int | None = None


@RobotConfig.register_subclass(REPLAY_TYPE)
@dataclass(kw_only=True)
class DatasetReplayRobotConfig(RobotConfig):
    """`--robot.type=predvla_replay`: the observations of one recorded episode, no hardware.

    Args:
        dataset_root: LeRobot dataset root whose episode is played (e.g. the training dataset).
        episode: Episode index to play; at its end it starts again from its first frame.
        cameras: Camera name -> camera config. Empty (default): every camera of the dataset under its recorded
            name (`{front: {type: predvla_replay, key: observation.images.front}}`). Give them to rename or drop
            cameras, as a miswired arm would.
        action_log: JSON-lines file that receives every action sent (`{"tick": t, "action": {motor: value}}`);
            None: actions are only kept in memory (`DatasetReplayRobot.actions`).
    """

    dataset_root: str
    episode: int = 0
    cameras: dict[str, CameraConfig] = field(default_factory=dict)
    action_log: str | None = None

    def __post_init__(self) -> None:
        layout = RecordedLayout.read(self.dataset_root)
        if not 0 <= self.episode < layout.total_episodes:
            raise ValueError(
                f"--robot.episode={self.episode}: {self.dataset_root} has episodes 0..{layout.total_episodes - 1}."
            )
        if not self.cameras:
            self.cameras = {
                name: DatasetReplayCameraConfig(key=f"{OBS_IMAGES}.{name}") for name in layout.cameras
            }
        for name, camera in self.cameras.items():
            if not isinstance(camera, DatasetReplayCameraConfig):
                continue
            camera.dataset_root = camera.dataset_root or self.dataset_root
            camera.episode = self.episode if camera.episode is None else camera.episode
            recorded = RecordedLayout.read(camera.dataset_root)
            shape = recorded.cameras.get(camera.key.removeprefix(f"{OBS_IMAGES}."))
            if shape is None:
                raise ValueError(
                    f"--robot.cameras.{name}.key={camera.key!r}: {camera.dataset_root} has the cameras "
                    f"{[f'{OBS_IMAGES}.{c}' for c in recorded.cameras]}."
                )
            camera.height, camera.width = camera.height or shape[0], camera.width or shape[1]
            camera.fps = camera.fps or recorded.fps
        super().__post_init__()
