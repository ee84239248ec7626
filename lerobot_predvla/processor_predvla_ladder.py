"""Pre- and post-processing of the ladder rungs: PredVLA's (front end, identity features, min-max actions)."""

from .configuration_predvla_ladder import PredVLALadderConfig
from .processor_predvla import make_predvla_pre_post_processors


def make_predvla_ladder_pre_post_processors(config: PredVLALadderConfig, dataset_stats: dict | None = None):
    return make_predvla_pre_post_processors(config, dataset_stats)
