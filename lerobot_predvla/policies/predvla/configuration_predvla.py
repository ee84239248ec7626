"""Configuration of the PredVLA policy (paper Tables 1 and 2)."""

from dataclasses import dataclass

from lerobot.configs import PreTrainedConfig
from lerobot.optim.schedulers import CosineDecayWithWarmupSchedulerConfig

from lerobot_predvla.policies.common.cached_features import CachedFeaturesConfig
from lerobot_predvla.policies.predvla.posterior_store import MOMENT_DTYPES

MODULE_NAMES = ("T", "V", "A_top", "A_bottom")
SHORT_HORIZON_TAU = (16.0, 8.0, 5.0, 2.0)
LONG_HORIZON_TAU = (30.0, 14.0, 8.0, 2.0)
LONG_HORIZON_SEQUENCE_LENGTH = 500
CORRUPTION_CHANNELS = ("vision", "proprio")
RECURRENCE_BACKENDS = ("auto", "python", "cpp")
COMPLEXITY_REDUCTIONS = ("sum", "mean")  # training C of Eq. 10: summed over the sequence, or its mean
ER_ADAM_STATES = ("fresh", "carried")  # error regression's Adam: afresh per control step, or per posterior
ER_OPTIMIZERS = ("adam", "gd")  # error regression's update: Table 2's Adam, or Section 3.5's c_q -= eta dE/dc_q
POSTERIOR_ADAMS = ("row", "dense")  # training posteriors' Adam: per demonstration in the batch, or the whole store
# Table 2 enables gradient clipping without a value; this one binds only on spikes (see `grad_clip_norm`).
GRAD_CLIP_NORM = 100.0
PREDVLA_PAPER_PARAMETERS = 675_732  # Table 1, at the paper's LIBERO layout (2 cameras, proprio 9, action 7)


@PreTrainedConfig.register_subclass("predvla")
@dataclass
class PredVLAConfig(CachedFeaturesConfig):
    """Configuration for PredVLA, a hierarchical predictive-coding RNN policy (Section 3).

    Defaults are the paper's short-horizon LIBERO settings (Tables 1 and 2); `PredVLAConfig.long_horizon()` is the
    LIBERO-10 preset (`'--policy.tau=[30,14,8,2]' --policy.sequence_length=500` on the command line). Inputs are
    the cached front-end features (`observation.vision_features`, `observation.language_features`,
    `observation.state`), never raw images. Vision and proprioception enter only the free energy minimised by error
    regression, language only the top module T (Eq. 4). The fields every policy type shares (dimensions, front end,
    decoders, optimiser, training length) are documented in `CachedFeaturesConfig`. docs/paper.md maps each field
    to the paper and gives our reading where the paper leaves a choice open.

    Args:
        language_encoder_dim: Output size of the frozen sentence encoder, before PCA (Table 1: 384).
        vision_encoder_dim: Output size of the frozen ResNet18 per camera, before PCA (Table 1: 512).
        module_dims: State sizes d_l of the modules (T, V, A_top, A_bottom) (Table 1: (64, 256, 256, 256)).
        latent_dim: Size r of each module's free variable c^l (Table 1: 64).
        bottleneck_dim: Width of the visual-to-action bottleneck z^VA = W_VA d^V (Eq. 5; Table 1: 256 -> 32 -> 256).
        tau: Time constants tau_l of (T, V, A_top, A_bottom), in control steps (Eqs. 3-4; Table 1: (16, 8, 5, 2)
            short horizon, (30, 14, 8, 2) long horizon).
        use_bottleneck: Keep the visual-to-action bottleneck V -> A_top (Eq. 5; default True). False is ablation A2
            (Table 6).
        use_efference_copy: Keep the efference copy of the previous action and proprioception predictions into V
            (Eq. 6; default True). False is ablation A3 (Table 6).
        recurrence_backend: Implementation of the recurrence's per-step loops, all with the same results; not a
            paper setting. "auto" (default): loops compiled in C++ for CPU float32/float64 where a compiler is
            present, else the Python loops; "cpp": the compiled loops or an error; "python": ATen ops on any device
            and dtype (docs/speed.md).
        flush_denormal: On a CPU, the policy sets `torch.set_flush_denormal(True)` for its process (default True),
            not a paper setting: values below 1.2e-38 become zero. Late in training weights and matmul outputs hold
            such values, where x86 arithmetic is slow: at step 8,000 of a full-scale run a training step with them
            kept took 1.79x as long (docs/speed.md, "Subnormal floats"). Nothing above 1.2e-38 changes.
        grad_clip_norm: Norm at which lerobot-train clips the network's gradient before Adam (default 100). Table 2
            enables clipping without a value; 100 catches spikes only, where a clip that binds at every step lets
            weight decay erase the priors' maps (docs/paper.md, "Choices the paper leaves open").
        posterior_lr: Adam learning rate of the training posteriors c_q (Section 3.4; Table 2: 1e-2, constant). They
            have their own Adam (`posterior_store.py`), so `--optimizer.*` flags and `grad_clip_norm` leave them alone.
        posterior_moments_dtype: Storage dtype of the training posteriors' Adam moments, not a paper setting:
            "float32" (default) or "bfloat16", a third less memory for large datasets (docs/speed.md); the update
            itself is computed in float32.
        posterior_adam: How the training posteriors' Adam steps: "row" (default), each demonstration's own Adam,
            stepped when it is in the batch; "dense", one Adam over the whole store. Section 3.4 makes the posteriors
            "model parameters" without saying which (`posterior_store.py`).
        lr_decay_to: None (default): constant learning rates, as in Table 2. A value: the network's learning rate
            decays along a cosine from `optimizer_lr` to it over `train_steps`; `posterior_lr` stays constant.
        lambda_v: Weight of the visual prediction error eps_v in training (Eq. 10; Table 2: 1).
        lambda_q: Weight of the proprioceptive prediction error eps_q in training (Eq. 10; Table 2: 1).
        lambda_a: Weight of the action negative log-likelihood (Eq. 10; Table 2: 1).
        complexity_weights: Training complexity weights w_l of (T, V, A_top, A_bottom) (Eq. 8; Table 2:
            (0.05, 0.02, 0.02, 0.01)).
        complexity_reduction: How the training loss reduces C_t over a sequence: "sum" (default) over its valid
            steps, as in the free energy of Eq. 9, since Eq. 10 puts the mask-normalised bar on the other terms but
            not on C; "mean", mask-normalised like them, is the other reading.
        open_loop_weight: Weight beta >= 0 of a training term not in the paper: Eq. 10's accuracy and action terms
            again on the open-loop rollout, every posterior at its prior (the rollout of `er_iterations=0`). 0
            (default) is Eq. 10 alone; it trains the prior chain that acting starts from.
        posteriors_fit_actions: True (default, Eq. 10 as written): each training posterior follows the gradient of
            all four terms, the action likelihood included. False, a departure: the action term reaches the network
            only (it is computed on a second rollout from the same posteriors, detached), so a training posterior is
            fitted to what error regression fits it to at test (the prediction errors and the complexity) and the
            network must read the actions from such states (docs/research/dynamics.md, the mechanism task). The
            losses are unchanged; training runs the recurrence twice.
        use_amp: LeRobot's field (default False: float32). True trains the recurrence and the heads in bfloat16
            under lerobot-train's autocast, the losses, posteriors and Adam states staying float32; error regression
            and the front end always run in full precision (docs/speed.md, "Mixed precision").
        er_window: Error-regression window W, in control steps (Section 3.5; Table 2: 40).
        er_iterations: Optimisation steps n_itr on the window's posteriors per control step (Table 2: 10). 0 is
            exact open-loop control (Section 3.5; ladder rung L1).
        er_deadline_ms: Time budget of error regression per control step, in milliseconds, not a paper setting: it
            runs as many of the `er_iterations` as fit, at least one, and logs how many. None (default) runs them
            all (docs/robot.md).
        er_lr: Step size eta of error regression's update (Section 3.5; Table 2: 0.05).
        er_adam_state: Error regression's Adam starts afresh at every control step ("fresh", default: each step's
            n_itr iterations are one optimisation, as Section 3.5 lists them), or each window posterior carries its
            moments and step count over the control steps it is optimised in ("carried"). Table 2 does not say which.
        er_optimizer: Error regression's update: "adam" (default; Table 2) or "gd", the plain step
            c_q <- c_q - eta dE/dc_q that Section 3.5 writes, with `er_lr` as eta (`er_adam_state` then unused).
        er_detach_priors: False (default): Section 3.5's dE/dc_q is the full derivative, including how each
            posterior moves the later priors c_p (Eqs. 1-2) through the states. True: the priors enter the complexity
            term as constants; the paper does not say which.
        er_complexity_weight: Complexity weight w_ER of every module during error regression (Section 4.3; Table 2:
            1.0).
        er_lambda_v: Weight of the visual prediction error during error regression (Eq. 9; default 1, as
            lambda_v). 0 is ablation A4 (Table 6).
        er_lambda_q: Weight of the proprioceptive prediction error during error regression (Eq. 9; default 1, as
            lambda_q). 0 is ablation A5 (Table 6).
        er_corruption_channel: Observation channel corrupted before error regression, "vision" or "proprio"
            (Section 4.4; Figure 5). None (default) corrupts nothing.
        er_corruption_alpha: Fraction alpha in [0, 1] of the window's observations of that channel that are replaced
            (Section 4.4: 0.25, 0.5, 0.75, 1; default 0). Control step t is replaced iff floor((t + 1) alpha) >
            floor(t alpha); for vision the count runs over refreshed frames.
        er_corruption_root: Root of a LeRobot dataset with the cached columns that supplies the replacing
            observations ("an unrelated episode", Section 4.4); required with `er_corruption_channel` (default None).
        er_corruption_episode: Episode of `er_corruption_root` whose step t replaces live step t, its last step once
            it has ended (default 0).
    """

    # Front end (Table 1).
    language_encoder_dim: int = 384
    vision_encoder_dim: int = 512

    # Recurrent architecture (Table 1).
    module_dims: tuple[int, int, int, int] = (64, 256, 256, 256)
    latent_dim: int = 64
    bottleneck_dim: int = 32
    tau: tuple[float, float, float, float] = SHORT_HORIZON_TAU
    use_bottleneck: bool = True
    use_efference_copy: bool = True
    recurrence_backend: str = "auto"
    flush_denormal: bool = True

    # Training (Table 2).
    grad_clip_norm: float = GRAD_CLIP_NORM
    posterior_lr: float = 1e-2
    posterior_moments_dtype: str = "float32"
    posterior_adam: str = "row"
    lr_decay_to: float | None = None
    lambda_v: float = 1.0
    lambda_q: float = 1.0
    lambda_a: float = 1.0
    complexity_weights: tuple[float, float, float, float] = (0.05, 0.02, 0.02, 0.01)
    complexity_reduction: str = "sum"
    open_loop_weight: float = 0.0  # not in Table 2: 0 is the paper's Eq. 10
    posteriors_fit_actions: bool = True  # False is not the paper's Eq. 10

    # Online error regression (Table 2).
    er_window: int = 40
    er_iterations: int = 10
    er_deadline_ms: float | None = None
    er_lr: float = 0.05
    er_adam_state: str = "fresh"
    er_optimizer: str = "adam"
    er_detach_priors: bool = False
    er_complexity_weight: float = 1.0
    er_lambda_v: float = 1.0
    er_lambda_q: float = 1.0
    er_corruption_channel: str | None = None
    er_corruption_alpha: float = 0.0
    er_corruption_root: str | None = None
    er_corruption_episode: int = 0

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
        if self.recurrence_backend not in RECURRENCE_BACKENDS:
            raise ValueError(
                f"`recurrence_backend` must be one of {RECURRENCE_BACKENDS}, got {self.recurrence_backend!r}."
            )
        if self.posterior_moments_dtype not in MOMENT_DTYPES:
            raise ValueError(
                f"`posterior_moments_dtype` must be one of {list(MOMENT_DTYPES)}, got {self.posterior_moments_dtype!r}."
            )
        if self.open_loop_weight < 0.0:
            raise ValueError(f"`open_loop_weight` must be >= 0, got {self.open_loop_weight}.")
        if min(self.tau) < 1.0:
            raise ValueError(f"`tau` values must be >= 1 (Eq. 3), got {self.tau}.")
        if self.er_window < 1 or self.er_iterations < 0:
            raise ValueError(
                f"`er_window` must be >= 1 and `er_iterations` >= 0, got {self.er_window}, {self.er_iterations}."
            )
        if self.er_adam_state not in ER_ADAM_STATES:
            raise ValueError(f"`er_adam_state` must be one of {ER_ADAM_STATES}, got {self.er_adam_state!r}.")
        if self.er_optimizer not in ER_OPTIMIZERS:
            raise ValueError(f"`er_optimizer` must be one of {ER_OPTIMIZERS}, got {self.er_optimizer!r}.")
        if self.posterior_adam not in POSTERIOR_ADAMS:
            raise ValueError(f"`posterior_adam` must be one of {POSTERIOR_ADAMS}, got {self.posterior_adam!r}.")
        if self.er_deadline_ms is not None and self.er_deadline_ms <= 0:
            raise ValueError(f"`er_deadline_ms` must be > 0 milliseconds (or None), got {self.er_deadline_ms}.")
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

    def get_scheduler_preset(self) -> CosineDecayWithWarmupSchedulerConfig | None:
        if self.lr_decay_to is None:
            return None  # Table 2: constant learning rate.
        return CosineDecayWithWarmupSchedulerConfig(
            num_warmup_steps=0, num_decay_steps=self.train_steps, peak_lr=self.optimizer_lr, decay_lr=self.lr_decay_to
        )
