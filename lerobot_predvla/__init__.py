"""PredVLA: a sub-million-parameter predictive-coding policy, as a LeRobot policy plugin."""

from lerobot_predvla.envs.configs import PredVLALiberoEnv  # registers --env.type=predvla_libero
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.policies.predvla.processor_predvla import make_predvla_pre_post_processors

__all__ = ["PredVLAConfig", "PredVLALiberoEnv", "PredVLAPolicy", "make_predvla_pre_post_processors"]
