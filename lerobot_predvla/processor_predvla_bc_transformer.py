"""Pre- and post-processing of BC-Transformer: PredVLA's (front end, identity features, min-max actions)."""

from .configuration_predvla_bc_transformer import PredVLABCTransformerConfig
from .processor_predvla import make_predvla_pre_post_processors


def make_predvla_bc_transformer_pre_post_processors(
    config: PredVLABCTransformerConfig, dataset_stats: dict | None = None
):
    return make_predvla_pre_post_processors(config, dataset_stats)
