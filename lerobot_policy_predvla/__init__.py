"""Discovery name for LeRobot's plugin loader: importing it registers the PredVLA policy types.

`predvla` (the paper's model and its ablations A1-A6), `predvla_bc_transformer` and `predvla_bc_rnn` (baselines
B1-B4) and `predvla_ladder` (ladder rungs L2-L5, L2b).
"""

from lerobot_predvla import PredVLAConfig, PredVLAPolicy, make_predvla_pre_post_processors
from lerobot_predvla.policies.bc_rnn.configuration_predvla_bc_rnn import PredVLABCRNNConfig
from lerobot_predvla.policies.bc_transformer.configuration_predvla_bc_transformer import PredVLABCTransformerConfig
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PredVLALadderConfig

__all__ = [
    "PredVLABCRNNConfig",
    "PredVLABCTransformerConfig",
    "PredVLAConfig",
    "PredVLALadderConfig",
    "PredVLAPolicy",
    "make_predvla_pre_post_processors",
]
