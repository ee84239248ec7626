"""Whole training episodes assembled from in-memory columns (Section 4.3).

LeRobot's per-key observation windows would decode every image of a 200-step window (about 10 s per
batch). PredVLA trains on cached feature columns only, so the dataset's feature, proprio and action
columns are read once from its parquet files, normalised by LeRobot's own normaliser step, and padded
per episode; a batch is then a lookup by `episode_index`.
"""

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.processor import NormalizerProcessorStep
from lerobot.processor.converters import batch_to_transition, transition_to_batch
from lerobot.utils.constants import ACTION, OBS_STATE
from torch import Tensor

from lerobot_predvla.columns import OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.policies.common.cached_features import CachedFeaturesConfig

SEQUENCE_COLUMNS = (OBS_VISION_FEATURES, OBS_STATE, ACTION)


def read_columns(root: Path, columns: list[str]) -> dict[str, np.ndarray]:
    """Read float vector columns of a LeRobot v3 dataset, rows in `index` order."""
    files = sorted((Path(root) / "data").glob("*/*.parquet"))
    if not files:
        raise FileNotFoundError(f"No parquet files under {Path(root) / 'data'}: is {root} a LeRobot dataset?")
    tables = [pq.read_table(f, columns=["index", *columns]) for f in files]
    order = np.argsort(np.concatenate([t.column("index").to_numpy() for t in tables]), kind="stable")
    out = {}
    for key in columns:
        chunks = []
        for t in tables:
            col = t.column(key).combine_chunks()
            if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
                col = col.flatten()
            chunks.append(col.to_numpy(zero_copy_only=False).astype(np.float32).reshape(len(t), -1))
        out[key] = np.concatenate(chunks)[order]
    return out


@dataclass
class EpisodeSequences:
    """Padded per-episode tensors: vision/state/action (episodes, L, dim), language (episodes, dim)."""

    vision: Tensor
    state: Tensor
    action: Tensor
    language: Tensor
    length: Tensor  # valid steps per episode, at most L

    @classmethod
    def from_dataset(cls, root: Path, config: CachedFeaturesConfig, stats: dict | None) -> "EpisodeSequences":
        columns = read_columns(root, ["episode_index", "frame_index", *SEQUENCE_COLUMNS, OBS_LANGUAGE_FEATURES])
        normalised = normalise(config, stats, {k: torch.from_numpy(columns[k]) for k in
                                               (*SEQUENCE_COLUMNS, OBS_LANGUAGE_FEATURES)})
        episode = columns["episode_index"][:, 0].astype(np.int64)
        frame = columns["frame_index"][:, 0].astype(np.int64)
        num_episodes, seq_len = int(episode.max()) + 1, config.sequence_length
        keep = frame < seq_len
        if not keep.all():
            cut = np.unique(episode[~keep])
            logging.warning(
                "PredVLA: %d episodes are longer than sequence_length=%d; their %d later frames are not "
                "trained on (raise --policy.sequence_length to use them).", len(cut), seq_len, int((~keep).sum())
            )
        idx = (torch.from_numpy(episode[keep]), torch.from_numpy(frame[keep]))

        def pad(key: str) -> Tensor:
            x = normalised[key][torch.from_numpy(keep)]
            table = x.new_zeros(num_episodes, seq_len, x.shape[-1])
            table[idx] = x
            return table

        language = torch.zeros(num_episodes, normalised[OBS_LANGUAGE_FEATURES].shape[-1])
        first = frame == 0
        language[torch.from_numpy(episode[first])] = normalised[OBS_LANGUAGE_FEATURES][torch.from_numpy(first)]
        length = torch.zeros(num_episodes, dtype=torch.long).index_add_(
            0, idx[0], torch.ones(len(idx[0]), dtype=torch.long)
        )
        return cls(pad(OBS_VISION_FEATURES), pad(OBS_STATE), pad(ACTION), language, length)

    def batch(self, episode_index: Tensor, device: torch.device) -> dict[str, Tensor]:
        """Time-major sequences of the given episodes and their validity mask (L, batch)."""
        e = episode_index.long().cpu()
        steps = torch.arange(self.vision.shape[1])
        return {
            "vision": self.vision[e].transpose(0, 1).to(device),
            "state": self.state[e].transpose(0, 1).to(device),
            "action": self.action[e].transpose(0, 1).to(device),
            "language": self.language[e].to(device),
            "valid": (steps[:, None] < self.length[e][None, :]).to(device),
        }


def normalise(config: CachedFeaturesConfig, stats: dict | None, columns: dict[str, Tensor]) -> dict[str, Tensor]:
    """Apply exactly the normalisation of the policy's preprocessor (LeRobot's NormalizerProcessorStep)."""
    features = {k: PolicyFeature(type=FeatureType.STATE, shape=(v.shape[-1],)) for k, v in columns.items()
                if k != ACTION}
    features[ACTION] = PolicyFeature(type=FeatureType.ACTION, shape=(columns[ACTION].shape[-1],))
    step = NormalizerProcessorStep(features=features, norm_map=config.normalization_mapping, stats=stats)
    return transition_to_batch(step(batch_to_transition(dict(columns))))
