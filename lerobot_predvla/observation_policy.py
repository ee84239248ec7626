"""Shared pieces of the policies that receive observations as inputs: baselines B1-B4 and ladder rungs L3-L5.

They read the same cached front-end columns as PredVLA (Sections 4.1, 4.4), train on whole episodes held in
memory (`EpisodeSequences`) with the negative log-likelihood of the same Gaussian-mixture action head, and
act without error regression. Vision is refreshed every `visual_refresh_interval` control steps and held in
between, in training and at evaluation alike. A missing or non-finite observation (`ObservationGuard`) is not
an input: the environment keeps its last available frame of that channel (zeros before the first).
"""

import logging
from dataclasses import dataclass, field
from pathlib import Path

import torch
from lerobot.configs import PreTrainedConfig
from lerobot.configs.types import NormalizationMode
from lerobot.optim.optimizers import AdamConfig
from lerobot.policies.pretrained import PreTrainedPolicy
from torch import Tensor

from .configuration_predvla import (
    cached_feature_normalization,
    check_fault_modes,
    use_dataset_frontend,
    validate_cached_features,
)
from .observation_guard import ObservationGuard
from .safe_loading import check_tensors, read_safetensors
from .sequence_table import EpisodeSequences
from .training_guard import TrainingGuard

BASELINE_TRAIN_STEPS = 50_000  # Section 4.4: baselines train for 50,000 steps (PredVLA: 30,000)


def held_vision(vision: Tensor, interval: int) -> Tensor:
    """Time-major vision with each step showing the latest refreshed frame: v[t - t mod interval]."""
    steps = torch.arange(vision.shape[0], device=vision.device)
    return vision[steps - steps % interval]


def observation_inputs(language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
    """Per-step input [v; q; l] (265); language (batch, 64) is broadcast over any leading time axis."""
    return torch.cat([vision, proprio, language.expand(*vision.shape[:-1], -1)], dim=-1)


def count_trainable(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


@dataclass
class ObservationPolicyConfig(PreTrainedConfig):
    """Fields shared by the baselines (B1-B4); see the subclasses' docstrings for their own fields.

    Args:
        language_dim: Language representation size after PCA (Table 1: 64).
        vision_dim_per_camera: Visual PCA components per camera (Table 1: 96).
        num_cameras: Number of camera views whose features are concatenated (Table 1: 2).
        proprio_dim: Proprioceptive dimension (Table 1: 9).
        action_dim: Action dimension (Table 1: 7).
        visual_refresh_interval: Vision is refreshed every this many control steps and held in between
            (Table 1: 4).
        frontend_dir: Front-end artefact that encodes live observations at evaluation, as in PredVLAConfig.
            None: the training dataset's copy (`meta/predvla_frontend`) when there is one.
        head_hidden_dim: Hidden width of the two-layer GMM action head (PredVLA's: 256).
        num_mixtures: Gaussian-mixture components K (Table 1: 5).
        min_action_scale: Lower bound added to the softplus scales (Table 1: 0.05).
        sequence_length: Episodes are cut or padded to this many steps in memory (Table 2 short: 200).
        train_steps: Paper's number of training steps (Section 4.4: 50,000 for the baselines); pass it to
            lerobot-train's `--steps` (configs/policy/B*.json do).
        train_batch_size: Paper's batch size (Table 2: 32); lerobot-train's `--batch_size`.
        optimizer_lr: Adam learning rate, constant. The paper picks it from a four-point sweep per baseline
            (values not given): sweep it with `--policy.optimizer_lr`.
        optimizer_weight_decay: Adam weight decay (Table 2: 1e-4).
        grad_clip_norm: Gradient-norm clip (PredVLA's 1.0).
        on_bad_observation: "mask" (default): a missing or non-finite observation channel is replaced by the
            environment's last available one; "raise": stop with an error. As PredVLAConfig.
        on_nonfinite_training: "stop" (default) or "skip" a batch with a non-finite loss or gradient. As
            PredVLAConfig.
    """

    language_dim: int = 64
    vision_dim_per_camera: int = 96
    num_cameras: int = 2
    proprio_dim: int = 9
    action_dim: int = 7
    visual_refresh_interval: int = 4
    frontend_dir: str | None = None
    head_hidden_dim: int = 256
    num_mixtures: int = 5
    min_action_scale: float = 0.05
    sequence_length: int = 200
    train_steps: int = BASELINE_TRAIN_STEPS
    train_batch_size: int = 32
    optimizer_lr: float = 1e-4
    optimizer_weight_decay: float = 1e-4
    grad_clip_norm: float = 1.0
    on_bad_observation: str = "mask"
    on_nonfinite_training: str = "stop"

    # Same normalisation as PredVLA: identity features, actions min-max scaled to [-1, 1].
    normalization_mapping: dict[str, NormalizationMode] = field(default_factory=cached_feature_normalization)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.visual_refresh_interval < 1 or self.sequence_length < 1:
            raise ValueError(
                f"`visual_refresh_interval` and `sequence_length` must be >= 1, got {self.visual_refresh_interval}"
                f" and {self.sequence_length}."
            )
        check_fault_modes(self)

    @property
    def vision_dim(self) -> int:
        return self.vision_dim_per_camera * self.num_cameras

    @property
    def observation_dim(self) -> int:
        """Input size per step: held vision, proprioception and language (192 + 9 + 64 = 265)."""
        return self.vision_dim + self.proprio_dim + self.language_dim

    def get_optimizer_preset(self) -> AdamConfig:
        return AdamConfig(
            lr=self.optimizer_lr, weight_decay=self.optimizer_weight_decay, grad_clip_norm=self.grad_clip_norm
        )

    def get_scheduler_preset(self) -> None:
        return None  # constant learning rate, as PredVLA (Table 2)

    def validate_features(self) -> None:
        validate_cached_features(self, type(self).__name__.removesuffix("Config"))

    @property
    def observation_delta_indices(self) -> None:
        return None  # whole episodes come from the in-memory EpisodeSequences

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None


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
        """Start-up line: our trainable parameters beside the paper's (Tables 4 and 5)."""
        ours = count_trainable(self)
        paper = "" if self.paper_parameters is None else (
            f" (paper: {self.paper_parameters:,}, {100 * (ours - self.paper_parameters) / self.paper_parameters:+.2f}%)"
        )
        logging.info("%s: %s trainable parameters%s", self.name, f"{ours:,}", paper)

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
        """The action of this control step, always finite (`ObservationGuard.safe_action`)."""
        return self.guard.safe_action(self.act(*self.observe(batch)))

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        return self.select_action(batch)[:, None]

    def act(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        raise NotImplementedError
