"""Observation corruption for error regression (Section 4.4; Section 5.3, "Sensitivity to corrupted observations").

For one channel at a time, a fraction alpha of the observations in the inference window is replaced by
observations of an unrelated episode; the other channel is untouched. A deterministic schedule gives the
exact fraction: item n is replaced iff floor((n+1) alpha) > floor(n alpha). Items are control steps for
proprioception and visual refreshes for vision (only refreshed frames enter the free energy).
"""

import math
from pathlib import Path

import numpy as np
import torch
from lerobot.configs.types import NormalizationMode
from lerobot.utils.constants import OBS_STATE
from torch import Tensor

from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.policies.common.sequence_table import read_columns
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

CHANNEL_KEYS = {"vision": OBS_VISION_FEATURES, "proprio": OBS_STATE}


def replaced(n: int, alpha: float) -> bool:
    """Whether item n is replaced: floor((n+1) alpha) > floor(n alpha)."""
    return math.floor((n + 1) * alpha) > math.floor(n * alpha)


class ObservationCorruption:
    """Replaces one channel's observations by those of an unrelated episode, on the alpha schedule."""

    def __init__(self, channel: str, alpha: float, source: Tensor, refresh_interval: int):
        self.key = CHANNEL_KEYS[channel]
        self.alpha = alpha
        self.source = source  # (steps, dim): the unrelated episode's observations of this channel
        # Vision is scheduled per refresh: all steps of a replaced refresh interval see the other frame.
        self.interval = refresh_interval if channel == "vision" else 1

    @classmethod
    def from_config(cls, config: PredVLAConfig) -> "ObservationCorruption | None":
        if config.er_corruption_channel is None:
            return None
        if config.normalization_mapping.get("STATE") != NormalizationMode.IDENTITY:
            raise ValueError(
                "`er_corruption_channel` replaces observations with raw dataset values, which needs the identity "
                f"normalisation of PredVLA's features (normalization_mapping STATE=IDENTITY), got "
                f"{config.normalization_mapping.get('STATE')}."
            )
        key = CHANNEL_KEYS[config.er_corruption_channel]
        columns = read_columns(Path(config.er_corruption_root), ["episode_index", "frame_index", key])
        rows = columns["episode_index"][:, 0] == config.er_corruption_episode
        if not rows.any():
            raise ValueError(
                f"`er_corruption_episode`={config.er_corruption_episode} is not an episode of "
                f"`er_corruption_root`={config.er_corruption_root}."
            )
        order = np.argsort(columns["frame_index"][rows, 0], kind="stable")
        source = torch.from_numpy(columns[key][rows][order])
        return cls(config.er_corruption_channel, config.er_corruption_alpha, source, config.visual_refresh_interval)

    def __call__(self, step: int, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """The observation of control step `step` (since reset), with this channel replaced if scheduled."""
        if not replaced(step // self.interval, self.alpha):
            return batch
        live = batch[self.key]
        other = self.source[min(step, len(self.source) - 1)].to(live.device, live.dtype)
        return {**batch, self.key: other.expand_as(live).clone()}
