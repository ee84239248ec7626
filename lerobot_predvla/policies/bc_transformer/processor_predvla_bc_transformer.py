"""Pre- and post-processing of BC-Transformer: PredVLA's (front end, identity features, min-max actions)."""

from lerobot_predvla.policies.bc_transformer.configuration_predvla_bc_transformer import PredVLABCTransformerConfig
from lerobot_predvla.policies.common.processors import make_cached_features_pre_post_processors


def make_predvla_bc_transformer_pre_post_processors(
    config: PredVLABCTransformerConfig, dataset_stats: dict | None = None
):
    return make_cached_features_pre_post_processors(config, dataset_stats)
