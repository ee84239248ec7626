"""Discovery name for LeRobot's plugin loader: importing it registers the PredVLA policy types."""

from lerobot_predvla import PredVLAConfig, PredVLAPolicy, make_predvla_pre_post_processors

__all__ = ["PredVLAConfig", "PredVLAPolicy", "make_predvla_pre_post_processors"]
