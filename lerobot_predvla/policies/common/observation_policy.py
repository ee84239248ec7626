"""Shared pieces of the policies that receive observations as inputs: baselines B1-B4 and ladder rungs L3-L5.

They read the same cached front-end columns as PredVLA (Sections 4.1, 4.4), train on whole episodes held in
memory (`EpisodeSequences`) with the negative log-likelihood of the same Gaussian-mixture action head, and
act without error regression. Vision is refreshed every `visual_refresh_interval` control steps and held in
between, in training and at evaluation alike. A missing or non-finite observation (`ObservationGuard`) is not
an input: the environment keeps its last available frame of that channel (zeros before the first).
"""

import logging
from dataclasses import dataclass
from pathlib import Path

import torch
from lerobot.policies.pretrained import PreTrainedPolicy
from torch import Tensor

from lerobot_predvla.policies.common.cached_features import (
    CachedFeaturesConfig,
    feature_layout,
    has_paper_layout,
    use_dataset_frontend,
)
from lerobot_predvla.policies.common.observation_guard import ObservationGuard
from lerobot_predvla.policies.common.sequence_table import EpisodeSequences
from lerobot_predvla.policies.common.training_guard import TrainingGuard
from lerobot_predvla.utils.parameters import count_parameters
from lerobot_predvla.utils.safe_loading import check_tensors, read_safetensors
from lerobot_predvla.utils.threads import acting_threads

BASELINE_TRAIN_STEPS = 50_000  # Section 4.5: baselines train for 50,000 steps (PredVLA: 30,000)


def held_vision(vision: Tensor, interval: int) -> Tensor:
    """Time-major vision with each step showing the latest refreshed frame: v[t - t mod interval]."""
    steps = torch.arange(vision.shape[0], device=vision.device)
    return vision[steps - steps % interval]


def observation_inputs(language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
    """Per-step input [v; q; l] (265); language (batch, 64) is broadcast over any leading time axis."""
    return torch.cat([vision, proprio, language.expand(*vision.shape[:-1], -1)], dim=-1)


@dataclass
class ObservationPolicyConfig(CachedFeaturesConfig):
    """Fields shared by the baselines (B1-B4); see the subclasses' docstrings for their own fields and
    `CachedFeaturesConfig` for the dimensions, front end, action head and optimiser fields.

    Defaults that differ from PredVLA's:
        train_steps: Section 4.5: 50,000 for the baselines; pass it to lerobot-train's `--steps`
            (configs/policy/B*.json do).
        optimizer_lr: Adam learning rate, constant. The paper picks it from a four-point sweep per baseline
            (values not given): sweep it with `--policy.optimizer_lr`.
    """

    train_steps: int = BASELINE_TRAIN_STEPS
    optimizer_lr: float = 1e-4

    @property
    def observation_dim(self) -> int:
        """Input size per step: held vision, proprioception and language (192 + 9 + 64 = 265)."""
        return self.vision_dim + self.proprio_dim + self.language_dim


class ObservationPolicy(PreTrainedPolicy):
    """Base of the observation-driven policies: data in memory, NLL training, held vision at evaluation.

    Subclasses set `config_class`, `name` and `paper_parameters` (the paper's count, printed beside ours at
    start-up) and implement `sequence_loss` and `act`.
    """

    config_class = ObservationPolicyConfig  # LeRobot requires both on every subclass; overridden by each policy
    name = "predvla_observation_policy"
    paper_parameters: int | None = None

    def __init__(self, config, dataset_stats: dict | None = None, dataset_meta=None, **kwargs):
        super().__init__(config)
        config.validate_features()
        self.config = config
        self.sequences: EpisodeSequences | None = None
        if dataset_meta is not None:
            use_dataset_frontend(config, Path(dataset_meta.root))
            self.sequences = EpisodeSequences.from_dataset(Path(dataset_meta.root), config, dataset_stats)
        self.training_guard = TrainingGuard(self, config.on_nonfinite_training, self.name)

    def log_parameter_count(self) -> None:
        """Start-up line: our trainable parameters and layout, beside the paper's count at its layout (Tables 4
        and 5)."""
        ours = count_parameters(self)
        paper = "" if self.paper_parameters is None or not has_paper_layout(self.config) else (
            f"; paper: {self.paper_parameters:,}, {100 * (ours - self.paper_parameters) / self.paper_parameters:+.2f}%"
        )
        logging.info("%s: %s trainable parameters (%s%s)", self.name, f"{ours:,}", feature_layout(self.config), paper)

    def get_optim_params(self) -> list[dict]:
        return [{"params": [p for p in self.parameters() if p.requires_grad]}]

    @classmethod
    def _load_as_safetensor(cls, model: "ObservationPolicy", model_file: str, map_location: str, strict: bool):
        """Weights read and checked whole (`safe_loading`) before any is loaded."""
        state, _ = read_safetensors(model_file)
        check_tensors(model_file, state, {k: v.detach().cpu() for k, v in model.state_dict().items()})
        model.load_state_dict(state)
        return model

    def training_sequences(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Whole episodes of the batch's `episode_index`, time-major, vision held between refreshes."""
        if self.sequences is None:
            raise RuntimeError(
                f"{type(self).__name__}.forward needs the training dataset: build the policy with `dataset_meta` "
                "(lerobot-train does)."
            )
        device = next(self.parameters()).device
        seq = self.sequences.batch(batch["episode_index"].reshape(-1), device)
        seq["vision"] = held_vision(seq["vision"], self.config.visual_refresh_interval)
        return seq

    def forward(self, batch: dict[str, Tensor], reduction: str = "mean") -> tuple[Tensor, dict]:
        if reduction != "mean":
            raise NotImplementedError(
                f"{type(self).__name__}'s loss is a mask-normalised mean over the sequence; reduction={reduction!r} "
                "is not supported."
            )
        loss, terms = self.sequence_loss(self.training_sequences(batch))
        values = {k: v.item() for k, v in terms.items()}
        return self.training_guard.check_loss(loss, values), values

    def sequence_loss(self, seq: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        raise NotImplementedError

    # ----- acting ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        self.control_step = 0
        # The latest available inputs per environment: the refreshed frame, proprioception and language.
        self.held: list[Tensor] | None = None
        if not hasattr(self, "guard"):
            self.guard = ObservationGuard.for_policy(self.config, self.name)
        self.guard.reset()

    def observe(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor, Tensor]:
        """(language, held vision, proprio) of this control step, each (batch, dim); an unavailable row keeps
        the environment's last available value."""
        values, available = self.guard(batch)
        if self.held is None:
            self.held = values  # unavailable rows are zeros
        refresh = self.control_step % self.config.visual_refresh_interval == 0
        self.held = [
            torch.where(ok[:, None], new, old) if (i != 1 or refresh) else old
            for i, (new, old, ok) in enumerate(zip(values, self.held, available, strict=True))
        ]
        self.control_step += 1
        return tuple(self.held)

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """The action of this control step, always finite (`ObservationGuard.safe_action`); on the CPU on one thread
        unless OMP_NUM_THREADS is set (utils/threads.py)."""
        observed = self.observe(batch)
        with acting_threads(observed[0].device):
            return self.guard.safe_action(self.act(*observed))

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        return self.select_action(batch)[:, None]

    def act(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        raise NotImplementedError
