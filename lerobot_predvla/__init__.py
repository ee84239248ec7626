"""PredVLA: a sub-million-parameter predictive-coding policy, as a LeRobot policy plugin.

Importing this package registers every policy type of the plugin with LeRobot (`--policy.type=predvla`,
`predvla_bc_transformer`, `predvla_bc_rnn`, `predvla_ladder`) and the `--env.type=predvla_libero` env; it is the
only registration point (`lerobot_policy_predvla`, the name LeRobot's plugin loader imports, re-exports it). It also
registers the `--robot.type=predvla_replay` robot and camera (a recorded episode played as a robot, docs/robot.md).
Every change it makes to LeRobot beyond registering types (replaced functions, environment variables) is made by the
one `install()` call below, and listed in lerobot_predvla/lerobot_integration.py and docs/lerobot_integration.md.
Below, it also hands PredVLA's publishing methods the Hub code (`PredVLAPolicy.publishing`), which sits above the
policies.
"""

from lerobot_predvla import lerobot_integration
from lerobot_predvla.hub import upload as hub_upload
from lerobot_predvla.policies import POLICY_TYPES
from lerobot_predvla.policies.bc_rnn.configuration_predvla_bc_rnn import PredVLABCRNNConfig
from lerobot_predvla.policies.bc_rnn.modeling_predvla_bc_rnn import PredVLABCRNNPolicy
from lerobot_predvla.policies.bc_transformer.configuration_predvla_bc_transformer import PredVLABCTransformerConfig
from lerobot_predvla.policies.bc_transformer.modeling_predvla_bc_transformer import PredVLABCTransformerPolicy
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PredVLALadderConfig
from lerobot_predvla.policies.ladder.modeling_predvla_ladder import PredVLALadderPolicy
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.policies.predvla.processor_predvla import make_predvla_pre_post_processors
from lerobot_predvla.robots import DatasetReplayRobotConfig
from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

PredVLAPolicy.publishing = hub_upload
lerobot_integration.install()

__all__ = [
    "DatasetReplayRobotConfig",
    "POLICY_TYPES",
    "PredVLABCRNNConfig",
    "PredVLABCRNNPolicy",
    "PredVLABCTransformerConfig",
    "PredVLABCTransformerPolicy",
    "PredVLAConfig",
    "PredVLALadderConfig",
    "PredVLALadderPolicy",
    "PredVLALiberoEnv",
    "PredVLAPolicy",
    "make_predvla_pre_post_processors",
]
