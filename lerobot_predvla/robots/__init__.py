"""Robots and cameras the plugin registers with LeRobot (`--robot.type=predvla_replay`)."""

from lerobot_predvla.robots.config_replay import DatasetReplayCameraConfig, DatasetReplayRobotConfig
from lerobot_predvla.robots.replay import DatasetReplayCamera, DatasetReplayRobot

__all__ = ["DatasetReplayCamera", "DatasetReplayCameraConfig", "DatasetReplayRobot", "DatasetReplayRobotConfig"]
