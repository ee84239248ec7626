"""The configuration every policy of this plugin shares: inputs are the cached front-end features.

PredVLA (`predvla`, `predvla_ladder`) and the observation-driven baselines (`predvla_bc_rnn`,
`predvla_bc_transformer`) read the same columns that `predvla convert` writes (Sections 3.1, 4.1), decode
actions with the same Gaussian-mixture head and train on whole episodes held in memory.
"""

import logging
from dataclasses import dataclass, field, fields
from pathlib import Path

from lerobot.configs import PreTrainedConfig
from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
from lerobot.optim.optimizers import AdamConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_predvla.columns import FRONTEND_META_DIR, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES

# The sizes a policy takes from its dataset's features; Table 1's defaults are LIBERO's Panda.
LAYOUT_FIELDS = ("num_cameras", "proprio_dim", "action_dim", "vision_dim_per_camera", "language_dim")
BAD_OBSERVATION_MODES = ("mask", "raise")  # acting on a missing or non-finite observation channel
NONFINITE_TRAINING_MODES = ("stop", "skip")  # training on a batch with a non-finite loss or gradient


def cached_feature_normalization() -> dict[str, NormalizationMode]:
    """Features are PCA outputs and raw proprioception (Section 3.1): identity. Actions are min-max scaled to
    [-1, 1], the range of the tanh component means (LIBERO's actions already lie there)."""
    return {
        "VISUAL": NormalizationMode.IDENTITY,
        "STATE": NormalizationMode.IDENTITY,
        "ENV": NormalizationMode.IDENTITY,
        "ACTION": NormalizationMode.MIN_MAX,
    }


def best_device() -> str:
    """The device LeRobot picks when none is set (its `auto_select_torch_device`: CUDA, MPS, XPU, else the CPU), without
    the log lines it writes about that choice."""
    from lerobot.configs import policies

    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        return policies.auto_select_torch_device().type
    finally:
        logging.disable(previous)


def use_dataset_frontend(config: "CachedFeaturesConfig", dataset_root: Path) -> None:
    """Point `config.frontend_dir` at the training dataset's artefact copy unless the user chose one.

    Read by the processor factory, which lerobot-train calls after building the policy.
    """
    frontend = Path(dataset_root) / FRONTEND_META_DIR
    if config.frontend_dir is None and frontend.is_dir():
        config.frontend_dir = str(frontend)


@dataclass
class CachedFeaturesConfig(PreTrainedConfig):
    """Fields shared by every policy type of the plugin (defaults: the paper's Tables 1 and 2).

    Args:
        language_dim: Language representation size after PCA (Table 1: 384 -> 64).
        vision_dim_per_camera: Visual PCA components per camera (Table 1: 512 -> 96).
        num_cameras: Number of camera views whose features are concatenated (Table 1: 2); set from the
            dataset's `observation.vision_features` (see `validate_cached_features`).
        proprio_dim: Proprioceptive dimension, joints 7 + gripper 2 (Table 1: 9); set from the dataset's
            `observation.state` (e.g. 8 for LeRobot's community LIBERO datasets, 6 for an SO-101).
        action_dim: Action dimension (Table 1: 7); set from the dataset's `action`.
        visual_refresh_interval: A fresh visual observation arrives every this many control steps and is held
            in between (Table 1: 4).
        frontend_dir: Front-end artefact (`predvla fit-frontend`) that encodes live observations at
            evaluation. None: the training dataset's copy (`meta/predvla_frontend`, written by `predvla
            convert`) when there is one. Its contents are stored in the checkpoint's preprocessor, so
            evaluation never reads this path.
        head_hidden_dim: Hidden width of the two-layer decoders, the GMM action head included (256).
        num_mixtures: Gaussian-mixture components K of the action head (Table 1: 5).
        min_action_scale: Lower bound added to the softplus scales of the action head (Table 1: 0.05).
        sequence_length: Training sequence length; episodes start at their first step and are padded to this
            length, longer episodes are cut (Table 2: 200 short, 500 long).
        train_steps: Paper's number of training steps (Table 2, PredVLA: 30,000). lerobot-train reads
            `--steps`; `predvla` commands and configs/policy pass this value.
        train_batch_size: Paper's batch size (Table 2: 32); passed to lerobot-train's `--batch_size`.
        optimizer_lr: Adam learning rate of the network weights, constant (Table 2, PredVLA: 6e-5).
        optimizer_weight_decay: Weight decay on network weights (Table 2: 1e-4).
        grad_clip_norm: Gradient-norm clip (Table 2: "enabled"; the value is not given, 1.0 is ours).
        on_bad_observation: What acting does with a missing or non-finite observation channel (vision
            features, proprioception) of one environment at one control step. "mask" (default): the channel
            is left out of that step (PredVLA: its prediction error leaves the free energy, Section 3.3; the
            baselines: it is replaced by zeros), counted and logged once per episode; the action stays
            finite. "raise": stop with an error naming the channel, environment and step (for users who
            would rather stop the robot). See docs/reliability.md.
        on_nonfinite_training: What training does when a batch's loss or gradient is non-finite. "stop"
            (default): lerobot-train stops with one line naming the step and the loss terms, before any
            checkpoint is written. "skip": the batch changes no weight (and no posterior); it is counted and
            logged.
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
    train_steps: int = 30_000
    train_batch_size: int = 32
    optimizer_lr: float = 6e-5
    optimizer_weight_decay: float = 1e-4
    grad_clip_norm: float = 1.0
    # Faults and bad input (docs/reliability.md).
    on_bad_observation: str = "mask"
    on_nonfinite_training: str = "stop"

    normalization_mapping: dict[str, NormalizationMode] = field(default_factory=cached_feature_normalization)

    def __post_init__(self) -> None:
        if not self.device:  # unset (every shipped config): LeRobot's choice, without its warning about "None"
            self.device = best_device()
        super().__post_init__()
        if self.visual_refresh_interval < 1:
            raise ValueError(f"`visual_refresh_interval` must be >= 1, got {self.visual_refresh_interval}.")
        if self.sequence_length < 1:
            raise ValueError(f"`sequence_length` must be >= 1, got {self.sequence_length}.")
        if self.on_bad_observation not in BAD_OBSERVATION_MODES:
            raise ValueError(
                f"`on_bad_observation` must be one of {BAD_OBSERVATION_MODES}, got {self.on_bad_observation!r}."
            )
        if self.on_nonfinite_training not in NONFINITE_TRAINING_MODES:
            raise ValueError(
                f"`on_nonfinite_training` must be one of {NONFINITE_TRAINING_MODES}, "
                f"got {self.on_nonfinite_training!r}."
            )

    @property
    def vision_dim(self) -> int:
        """Concatenated visual dimension (Table 1: 2 x 96 = 192)."""
        return self.vision_dim_per_camera * self.num_cameras

    def get_optimizer_preset(self) -> AdamConfig:
        # Adam with L2 weight decay, network weights only (PredVLA's posteriors: posterior_store.py).
        return AdamConfig(
            lr=self.optimizer_lr, weight_decay=self.optimizer_weight_decay, grad_clip_norm=self.grad_clip_norm
        )

    def get_scheduler_preset(self) -> None:
        return None  # Table 2: constant learning rate.

    def validate_features(self) -> None:
        validate_cached_features(self, type(self).__name__.removesuffix("Config"))

    @property
    def observation_delta_indices(self) -> None:
        # Sequences are assembled from an in-memory table keyed by episode (policies/common/sequence_table.py).
        return None

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None


def feature_layout(config: CachedFeaturesConfig) -> str:
    """The input and output sizes a policy was built for, e.g. "2 cameras x 96, state 9, action 7, language 64"."""
    return (
        f"{config.num_cameras} camera{'s' if config.num_cameras != 1 else ''} x {config.vision_dim_per_camera}, "
        f"state {config.proprio_dim}, action {config.action_dim}, language {config.language_dim}"
    )


def has_paper_layout(config: CachedFeaturesConfig) -> bool:
    """Whether the sizes are Table 1's (LIBERO's Panda), where the paper's parameter counts apply."""
    defaults = {f.name: f.default for f in fields(type(config))}
    return all(getattr(config, name) == defaults[name] for name in LAYOUT_FIELDS)


def validate_cached_features(config: CachedFeaturesConfig, policy_name: str) -> None:
    """Take the sizes from the features (or, for a bare config, set the features from the sizes) and check them.

    Built from a dataset (or a checkpoint), the policy follows its features: `proprio_dim` is the size of
    `observation.state`, `action_dim` that of `action`, and `num_cameras` the size of
    `observation.vision_features` over `vision_dim_per_camera`, so any robot's layout works. The language
    size is the front end's and must match `language_dim`.
    """
    if not config.input_features:  # A bare config: the inputs are fixed by the dimensions.
        config.input_features = {
            OBS_VISION_FEATURES: PolicyFeature(type=FeatureType.STATE, shape=(config.vision_dim,)),
            OBS_LANGUAGE_FEATURES: PolicyFeature(type=FeatureType.STATE, shape=(config.language_dim,)),
            OBS_STATE: PolicyFeature(type=FeatureType.STATE, shape=(config.proprio_dim,)),
        }
    if not config.output_features:
        config.output_features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(config.action_dim,))}
    sizes = {}
    for key, features in (
        (OBS_VISION_FEATURES, config.input_features),
        (OBS_LANGUAGE_FEATURES, config.input_features),
        (OBS_STATE, config.input_features),
        (ACTION, config.output_features),
    ):
        feature = features.get(key)
        if feature is None:
            raise ValueError(
                f"{policy_name} needs the feature '{key}'; the dataset or environment provides "
                f"{sorted(features)}. Add the cached columns with `predvla convert` (docs/own_dataset.md)."
            )
        if len(feature.shape) != 1:
            raise ValueError(f"Feature '{key}' must be a vector, got shape {tuple(feature.shape)}.")
        sizes[key] = int(feature.shape[0])
    if sizes[OBS_VISION_FEATURES] % config.vision_dim_per_camera:
        raise ValueError(
            f"'{OBS_VISION_FEATURES}' has {sizes[OBS_VISION_FEATURES]} dimensions, not a multiple of "
            f"vision_dim_per_camera={config.vision_dim_per_camera}: set --policy.vision_dim_per_camera to the front "
            f"end's components per camera (a dataset converted with --oracle: its {sizes[OBS_VISION_FEATURES]} poses)."
        )
    if sizes[OBS_LANGUAGE_FEATURES] != config.language_dim:
        raise ValueError(
            f"'{OBS_LANGUAGE_FEATURES}' has {sizes[OBS_LANGUAGE_FEATURES]} dimensions, language_dim is "
            f"{config.language_dim}."
        )
    config.num_cameras = sizes[OBS_VISION_FEATURES] // config.vision_dim_per_camera
    config.proprio_dim = sizes[OBS_STATE]
    config.action_dim = sizes[ACTION]
    # Only the cached features are inputs; images and other columns are not part of the policy.
    config.input_features = {
        key: PolicyFeature(type=FeatureType.STATE, shape=(sizes[key],))
        for key in (OBS_VISION_FEATURES, OBS_LANGUAGE_FEATURES, OBS_STATE)
    }
    config.output_features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(config.action_dim,))}
