"""Pre- and post-processing of PredVLA: the shared pipelines (front end, identity features, min-max actions)."""

from lerobot_predvla.policies.common.processors import make_cached_features_pre_post_processors
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig


def make_predvla_pre_post_processors(config: PredVLAConfig, dataset_stats: dict | None = None):
    return make_cached_features_pre_post_processors(config, dataset_stats)
