"""Configuration of the PredVLA policy (paper Tables 1 and 2)."""

from dataclasses import dataclass, field
from pathlib import Path

from lerobot.configs import PreTrainedConfig
from lerobot.configs.types import FeatureType, NormalizationMode, PolicyFeature
from lerobot.optim.optimizers import AdamConfig
from lerobot.utils.constants import ACTION, OBS_STATE

# Cached front-end columns written by the converter (`predvla convert`).
OBS_VISION_FEATURES = "observation.vision_features"
OBS_LANGUAGE_FEATURES = "observation.language_features"
FRONTEND_META_DIR = "meta/predvla_frontend"  # the front-end artefact copy a converted dataset carries

MODULE_NAMES = ("T", "V", "A_top", "A_bottom")
SHORT_HORIZON_TAU = (16.0, 8.0, 5.0, 2.0)
LONG_HORIZON_TAU = (30.0, 14.0, 8.0, 2.0)
LONG_HORIZON_SEQUENCE_LENGTH = 500
CORRUPTION_CHANNELS = ("vision", "proprio")
COMPLEXITY_REDUCTIONS = ("sum", "mean")  # training C of Eq. 10: summed over the sequence, or its mean
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


def check_fault_modes(config) -> None:
    """Validate `on_bad_observation` and `on_nonfinite_training` (PredVLA and the baselines)."""
    if config.on_bad_observation not in BAD_OBSERVATION_MODES:
        raise ValueError(
            f"`on_bad_observation` must be one of {BAD_OBSERVATION_MODES}, got {config.on_bad_observation!r}."
        )
    if config.on_nonfinite_training not in NONFINITE_TRAINING_MODES:
        raise ValueError(
            f"`on_nonfinite_training` must be one of {NONFINITE_TRAINING_MODES}, got {config.on_nonfinite_training!r}."
        )


def use_dataset_frontend(config, dataset_root: Path) -> None:
    """Point `config.frontend_dir` at the training dataset's artefact copy unless the user chose one.

    Read by the processor factory, which lerobot-train calls after building the policy.
    """
    frontend = Path(dataset_root) / FRONTEND_META_DIR
    if config.frontend_dir is None and frontend.is_dir():
        config.frontend_dir = str(frontend)


@PreTrainedConfig.register_subclass("predvla")
@dataclass
class PredVLAConfig(PreTrainedConfig):
    """Configuration for PredVLA, a hierarchical predictive-coding RNN policy.

    Defaults are the paper's short-horizon LIBERO settings (Tables 1 and 2). The long-horizon preset
    (LIBERO-10) is `PredVLAConfig.long_horizon()`, i.e. `--policy.tau=[30,14,8,2]
    --policy.sequence_length=500` on the command line.

    Inputs are the cached front-end features, never raw images: `observation.vision_features` (two
    cameras x 96 PCA components), `observation.language_features` (64 PCA components of the
    all-MiniLM-L6-v2 instruction embedding) and `observation.state` (7 joints + 2 gripper). The network
    never receives them as inputs: vision and proprioception only enter the free energy minimised by
    error regression; language enters the top module T (Eq. 4).

    Args:
        language_dim: Language representation size after PCA (Table 1: 384 -> 64).
        language_encoder_dim: Output size of the frozen sentence encoder (Table 1: 384).
        vision_dim_per_camera: Visual PCA components per camera (Table 1: 512 -> 96).
        vision_encoder_dim: Output size of the frozen ResNet18 per camera (Table 1: 512).
        num_cameras: Number of camera views whose features are concatenated (Table 1: 2).
        proprio_dim: Proprioceptive dimension, joints 7 + gripper 2 (Table 1: 9).
        action_dim: Action dimension (Table 1: 7).
        visual_refresh_interval: A fresh visual observation arrives every this many control steps
            (Table 1: 4). Visual prediction errors count only on those steps, in training and in
            error regression.
        module_dims: Deterministic state sizes d_l of (T, V, A_top, A_bottom) (Table 1: 64/256/256/256).
        latent_dim: Size r of each module's free variable c^l (Table 1: 64 per module).
        bottleneck_dim: Width of the visual-to-action bottleneck W_VA (Eq. 5; Table 1: 256 -> 32 -> 256).
        head_hidden_dim: Hidden width of the two-layer v, q and action decoders.
        num_mixtures: Gaussian-mixture components K of the action head (Table 1: 5).
        min_action_scale: Lower bound added to the softplus scales of the action head (Table 1: 0.05).
        tau: Time constants of (T, V, A_top, A_bottom) (Table 1 short horizon: (16, 8, 5, 2);
            long horizon: (30, 14, 8, 2)).
        sequence_length: Training sequence length; episodes start at their first step and are padded
            to this length, longer episodes are cut (Table 2: 200 short, 500 long).
        train_steps: Paper's number of training steps (Table 2: 30,000). lerobot-train reads
            `--steps`; `predvla` commands and configs/policy pass this value.
        train_batch_size: Paper's batch size (Table 2: 32); passed to lerobot-train's `--batch_size`.
        optimizer_lr: Adam learning rate of the network weights (Table 2: 6e-5, constant).
        posterior_lr: Adam learning rate of the training posteriors c_q (Table 2: 1e-2).
        optimizer_weight_decay: Weight decay on network weights only (Table 2: 1e-4); the posteriors
            have none.
        grad_clip_norm: Gradient-norm clip (Table 2: "enabled"; the value is not given, 1.0 is ours).
        lambda_v: Weight of the visual prediction error (Eq. 10; Table 2: 1).
        lambda_q: Weight of the proprioceptive prediction error (Eq. 10; Table 2: 1).
        lambda_a: Weight of the action negative log-likelihood (Eq. 10; Table 2: 1).
        complexity_weights: w_l of (T, V, A_top, A_bottom) in the training complexity term (Eq. 8;
            Table 2: (0.05, 0.02, 0.02, 0.01)).
        complexity_reduction: How the training loss reduces C_t over a sequence. "sum" (default): C is the
            sum of C_t over the sequence's valid steps, as in the free energy of Eq. 9, since Eq. 10 puts the
            mask-normalised bar on the errors and the NLL but not on C; averaged over the batch. "mean": the
            mask-normalised mean, like the other terms (about T times weaker; it leaves the priors far from
            the posteriors on short schedules, see the README).
        er_window: Error-regression window W in control steps (Table 2: 40).
        er_iterations: Adam iterations n_itr per control step (Table 2: 10). 0 is exact open loop.
        er_lr: Adam step size eta of error regression (Table 2: 0.05).
        er_complexity_weight: w_ER, the complexity weight of every module during error regression
            (Table 2: 1.0).
        er_lambda_v: Visual prediction-error weight during error regression (1; 0 is ablation A4).
        er_lambda_q: Proprioceptive prediction-error weight during error regression (1; 0 is A5).
        use_bottleneck: Keep the visual-to-action bottleneck V -> A_top (Eq. 5); False is ablation A2.
        frontend_dir: Front-end artefact (`predvla fit-frontend`) that encodes live observations at
            evaluation. None: the training dataset's copy (`meta/predvla_frontend`, written by `predvla
            convert`) when there is one. Its contents are stored in the checkpoint's preprocessor, so
            evaluation never reads this path.
        use_efference_copy: Keep the efference copy A -> V of the model's own previous action and
            proprioception predictions (Eq. 6); False is ablation A3.
        er_corruption_channel: Observation channel corrupted before error regression (Section 4.4,
            "Sensitivity to corrupted observations"): "vision" or "proprio"; None (default) corrupts nothing.
            The other channel is left untouched.
        er_corruption_alpha: Fraction alpha in [0, 1] of the window's observations of that channel replaced
            (paper: 0.25, 0.5, 0.75, 1.0). Control step t is replaced iff floor((t+1) alpha) > floor(t alpha),
            so every window of W steps holds exactly W alpha replaced steps when W alpha is an integer; for
            vision the schedule counts visual refreshes, so the fraction applies to the fresh frames.
        er_corruption_root: Root of a LeRobot dataset with the cached columns, source of the replacing
            observations (an unrelated episode); required with `er_corruption_channel`.
        er_corruption_episode: Episode of `er_corruption_root` whose observations replace the live ones: step t
            of the live episode receives its step t (its last step once it has ended).
        on_bad_observation: What acting does with a missing or non-finite observation channel (vision
            features, proprioception) of one environment at one control step. "mask" (default): its
            prediction error is left out of that step's free energy (Section 3.3), counted and logged once per
            episode; the action stays finite. "raise": stop with an error naming the channel, environment and
            step (for users who would rather stop the robot). See docs/reliability.md.
        on_nonfinite_training: What training does when a batch's loss or gradient is non-finite. "stop"
            (default): lerobot-train stops with one line naming the step and the loss terms, before any
            checkpoint is written. "skip": the batch changes no weight and no posterior; it is counted and
            logged.
    """

    # Front end (Table 1).
    language_dim: int = 64
    language_encoder_dim: int = 384
    vision_dim_per_camera: int = 96
    vision_encoder_dim: int = 512
    num_cameras: int = 2
    proprio_dim: int = 9
    action_dim: int = 7
    visual_refresh_interval: int = 4

    # Recurrent architecture (Table 1).
    module_dims: tuple[int, int, int, int] = (64, 256, 256, 256)
    latent_dim: int = 64
    bottleneck_dim: int = 32
    head_hidden_dim: int = 256
    num_mixtures: int = 5
    min_action_scale: float = 0.05
    tau: tuple[float, float, float, float] = SHORT_HORIZON_TAU
    use_bottleneck: bool = True
    use_efference_copy: bool = True
    frontend_dir: str | None = None

    # Training (Table 2).
    sequence_length: int = 200
    train_steps: int = 30_000
    train_batch_size: int = 32
    optimizer_lr: float = 6e-5
    posterior_lr: float = 1e-2
    optimizer_weight_decay: float = 1e-4
    grad_clip_norm: float = 1.0
    lambda_v: float = 1.0
    lambda_q: float = 1.0
    lambda_a: float = 1.0
    complexity_weights: tuple[float, float, float, float] = (0.05, 0.02, 0.02, 0.01)
    complexity_reduction: str = "sum"

    # Online error regression (Table 2).
    er_window: int = 40
    er_iterations: int = 10
    er_lr: float = 0.05
    er_complexity_weight: float = 1.0
    er_lambda_v: float = 1.0
    er_lambda_q: float = 1.0
    er_corruption_channel: str | None = None
    er_corruption_alpha: float = 0.0
    er_corruption_root: str | None = None
    er_corruption_episode: int = 0
    # Faults and bad input (docs/reliability.md).
    on_bad_observation: str = "mask"
    on_nonfinite_training: str = "stop"

    normalization_mapping: dict[str, NormalizationMode] = field(default_factory=cached_feature_normalization)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.module_dims = tuple(int(d) for d in self.module_dims)
        self.tau = tuple(float(t) for t in self.tau)
        self.complexity_weights = tuple(float(w) for w in self.complexity_weights)
        for name, value in (("module_dims", self.module_dims), ("tau", self.tau),
                            ("complexity_weights", self.complexity_weights)):
            if len(value) != len(MODULE_NAMES):
                raise ValueError(f"`{name}` needs one value per module {MODULE_NAMES}, got {value}.")
        if self.complexity_reduction not in COMPLEXITY_REDUCTIONS:
            raise ValueError(
                f"`complexity_reduction` must be one of {COMPLEXITY_REDUCTIONS}, got {self.complexity_reduction!r}."
            )
        if min(self.tau) < 1.0:
            raise ValueError(f"`tau` values must be >= 1 (Eq. 3), got {self.tau}.")
        if self.er_window < 1 or self.er_iterations < 0:
            raise ValueError(
                f"`er_window` must be >= 1 and `er_iterations` >= 0, got {self.er_window}, {self.er_iterations}."
            )
        if self.visual_refresh_interval < 1:
            raise ValueError(f"`visual_refresh_interval` must be >= 1, got {self.visual_refresh_interval}.")
        if self.sequence_length < 1:
            raise ValueError(f"`sequence_length` must be >= 1, got {self.sequence_length}.")
        check_fault_modes(self)
        if self.er_corruption_channel not in (None, *CORRUPTION_CHANNELS):
            raise ValueError(
                f"`er_corruption_channel` must be one of {CORRUPTION_CHANNELS} or None, "
                f"got {self.er_corruption_channel!r}."
            )
        if not 0.0 <= self.er_corruption_alpha <= 1.0:
            raise ValueError(f"`er_corruption_alpha` must lie in [0, 1], got {self.er_corruption_alpha}.")
        if self.er_corruption_channel is not None and self.er_corruption_root is None:
            raise ValueError(
                "`er_corruption_channel` needs `er_corruption_root`: a LeRobot dataset root with the cached columns "
                "(e.g. --policy.er_corruption_root=datasets/libero_object --policy.er_corruption_episode=3)."
            )

    @classmethod
    def long_horizon(cls, **kwargs) -> "PredVLAConfig":
        """The paper's LIBERO-10 preset: tau (30, 14, 8, 2) and 500-step training sequences."""
        kwargs.setdefault("tau", LONG_HORIZON_TAU)
        kwargs.setdefault("sequence_length", LONG_HORIZON_SEQUENCE_LENGTH)
        return cls(**kwargs)

    @property
    def vision_dim(self) -> int:
        """Concatenated visual dimension (Table 1: 2 x 96 = 192)."""
        return self.vision_dim_per_camera * self.num_cameras

    def get_optimizer_preset(self) -> AdamConfig:
        # Adam with L2 weight decay; the posterior group overrides lr and weight decay
        # (see PredVLAPolicy.get_optim_params).
        return AdamConfig(
            lr=self.optimizer_lr,
            weight_decay=self.optimizer_weight_decay,
            grad_clip_norm=self.grad_clip_norm,
        )

    def get_scheduler_preset(self) -> None:
        return None  # Table 2: constant learning rate.

    def validate_features(self) -> None:
        validate_cached_features(self, "PredVLA")

    @property
    def observation_delta_indices(self) -> None:
        # Sequences are assembled from an in-memory table keyed by episode (see sequence_table.py).
        return None

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None


def validate_cached_features(config, policy_name: str) -> None:
    """Check (and, for a bare config, set) the cached front-end inputs and the action output.

    Shared by PredVLA and the policies of the paper's baselines and ladder, which read the same columns.
    `config` needs `vision_dim`, `language_dim`, `proprio_dim` and `action_dim`.
    """
    expected = {
        OBS_VISION_FEATURES: config.vision_dim,
        OBS_LANGUAGE_FEATURES: config.language_dim,
        OBS_STATE: config.proprio_dim,
    }
    if not config.input_features:  # A bare config: the inputs are fixed by the dimensions.
        config.input_features = {
            key: PolicyFeature(type=FeatureType.STATE, shape=(dim,)) for key, dim in expected.items()
        }
    for key, dim in expected.items():
        feature = config.input_features.get(key)
        if feature is None:
            raise ValueError(
                f"{policy_name} needs the input feature '{key}' of shape ({dim},); the dataset or environment "
                f"provides {sorted(config.input_features)}. Convert LIBERO data with `predvla convert`."
            )
        if tuple(feature.shape) != (dim,):
            raise ValueError(f"Input feature '{key}' must have shape ({dim},), got {tuple(feature.shape)}.")
    if not config.output_features:
        config.output_features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(config.action_dim,))}
    action = config.output_features.get(ACTION)
    if action is None or tuple(action.shape) != (config.action_dim,):
        shape = None if action is None else tuple(action.shape)
        raise ValueError(f"Output feature '{ACTION}' must have shape ({config.action_dim},), got {shape}.")
    # Only the cached features are inputs; images and other columns are not part of the policy.
    config.input_features = {
        key: PolicyFeature(type=FeatureType.STATE, shape=(dim,)) for key, dim in expected.items()
    }
