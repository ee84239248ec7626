"""PredVLA: a sub-million-parameter predictive-coding policy, as a LeRobot policy plugin."""

from .configuration_predvla import PredVLAConfig
from .libero.eval_config import PredVLALiberoEnv  # registers --env.type=predvla_libero
from .modeling_predvla import PredVLAPolicy
from .processor_predvla import make_predvla_pre_post_processors

__all__ = ["PredVLAConfig", "PredVLALiberoEnv", "PredVLAPolicy", "make_predvla_pre_post_processors"]
