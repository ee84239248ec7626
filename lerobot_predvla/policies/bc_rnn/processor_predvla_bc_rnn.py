"""Pre- and post-processing of BC-RNN: PredVLA's (front end, identity features, min-max actions)."""

from lerobot_predvla.policies.bc_rnn.configuration_predvla_bc_rnn import PredVLABCRNNConfig
from lerobot_predvla.policies.common.processors import make_cached_features_pre_post_processors


def make_predvla_bc_rnn_pre_post_processors(config: PredVLABCRNNConfig, dataset_stats: dict | None = None):
    return make_cached_features_pre_post_processors(config, dataset_stats)
