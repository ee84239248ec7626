"""Pre- and post-processing of the ladder rungs: PredVLA's (front end, identity features, min-max actions)."""

from lerobot_predvla.policies.common.processors import make_cached_features_pre_post_processors
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PredVLALadderConfig


def make_predvla_ladder_pre_post_processors(config: PredVLALadderConfig, dataset_stats: dict | None = None):
    return make_cached_features_pre_post_processors(config, dataset_stats)
