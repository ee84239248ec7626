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
    """Configuration for PredVLA, a hierarchical predictive-coding RNN policy.

    Defaults are the paper's short-horizon LIBERO settings (Tables 1 and 2). The long-horizon preset
    (LIBERO-10) is `PredVLAConfig.long_horizon()`, i.e. `--policy.tau=[30,14,8,2]
    --policy.sequence_length=500` on the command line.

    Inputs are the cached front-end features, never raw images: `observation.vision_features` (two
    cameras x 96 PCA components), `observation.language_features` (64 PCA components of the
    all-MiniLM-L6-v2 instruction embedding) and `observation.state` (7 joints + 2 gripper). Built from a
    dataset, `num_cameras`, `proprio_dim` and `action_dim` follow its features (any robot; see
    `validate_cached_features`); the parameter count follows and is logged. The network
    never receives them as inputs: vision and proprioception only enter the free energy minimised by
    error regression; language enters the top module T (Eq. 4).

    Fields shared with the other policy types (dimensions, front end, decoders, optimiser) are documented in
    `CachedFeaturesConfig`; the paper's learning rate and step count are PredVLA's defaults there.

    Args:
        language_encoder_dim: Output size of the frozen sentence encoder (Table 1: 384).
        vision_encoder_dim: Output size of the frozen ResNet18 per camera (Table 1: 512).
        module_dims: Deterministic state sizes d_l of (T, V, A_top, A_bottom) (Table 1: 64/256/256/256).
        latent_dim: Size r of each module's free variable c^l (Table 1: 64 per module).
        bottleneck_dim: Width of the visual-to-action bottleneck W_VA (Eq. 5; Table 1: 256 -> 32 -> 256).
        tau: Time constants of (T, V, A_top, A_bottom) (Table 1 short horizon: (16, 8, 5, 2);
            long horizon: (30, 14, 8, 2)).
        posterior_lr: Adam learning rate of the training posteriors c_q (Table 2: 1e-2). Each demonstration's
            posteriors are stepped by their own Adam when the demonstration is in the batch, after LeRobot's
            optimizer step (`PredVLAPolicy.update`; `posterior_store.py` says why this is the paper's per-episode
            reading). They are not parameters of LeRobot's optimizer, so `--optimizer.*` flags and gradient
            clipping (`grad_clip_norm`) apply to the network only.
        grad_clip_norm: Clip of the network gradient's norm, applied by lerobot-train before Adam (Table 2:
            "enabled", value not given; `CachedFeaturesConfig`'s 1.0 for the baselines). 100 for PredVLA, above
            every gradient norm logged over the first 12,000 steps of Table 2's recipe on libero_object (8.6 to
            74, median 41), so it only catches spikes. At 1.0 the clip bound at every step (scale 0.02-0.06), and
            torch.optim.Adam's weight decay, added to the clipped gradient unscaled, then outweighed the loss
            gradient 2-10x on the priors' maps of T, V and A_top (trained by the complexity term alone): their
            norms fell from 4.6 to 0.2-0.6 in 10,000 steps (docs/research/table2.md; `predvla inspect` shows these
            forces). The CPU recipes (`configs/policy/predvla_cpu*.json`) keep the 1.0 they were measured with.
        posterior_moments_dtype: Storage of the training posteriors' Adam moments: "float32" (default) or
            "bfloat16", a third less memory for large datasets (LIBERO-90, 4,500 demonstrations x 500 steps:
            4.6 GB instead of 6.9 GB; docs/speed.md). The update is computed in float32 and the posteriors stay
            float32; the moments are rounded to ~3 significant digits when stored.
        posterior_adam: How the training posteriors' Adam steps. "row" (default): each demonstration's posteriors
            are stepped only when it is in the batch, with its own step count (`posterior_store.py`). "dense": one
            Adam over the whole store, as `torch.optim.Adam` on a single tensor would do: rows absent from the
            batch see a zero gradient, so their moments decay while stale momentum keeps moving them. Section 3.4
            makes the posteriors "model parameters" without saying which; dense costs one pass over the store
            per step.
        lr_decay_to: None (default): constant learning rates (Table 2). A value: the network learning rate decays
            along a cosine from `optimizer_lr` to this value over the run (`--steps`, at most `train_steps`;
            LeRobot's `cosine_decay_with_warmup`, no warm-up); `posterior_lr` stays constant. An option for
            experiments (docs/research/libero_object_cpu.md measures a cool-down with it).
        lambda_v: Weight of the visual prediction error (Eq. 10; Table 2: 1).
        lambda_q: Weight of the proprioceptive prediction error (Eq. 10; Table 2: 1). Proprioception is raw radians,
            so at 1 its error is tiny against the complexity term; the CPU recipe
            `configs/policy/predvla_cpu_lambda_q100.json` trains with 100 (about one over the joint angles' variance)
            and keeps `er_lambda_q` at 1 (docs/research/lambda_q100.md).
        lambda_a: Weight of the action negative log-likelihood (Eq. 10; Table 2: 1).
        complexity_weights: w_l of (T, V, A_top, A_bottom) in the training complexity term (Eq. 8;
            Table 2: (0.05, 0.02, 0.02, 0.01)).
        complexity_reduction: How the training loss reduces C_t over a sequence. "sum" (default): C is the
            sum of C_t over the sequence's valid steps, as in the free energy of Eq. 9, since Eq. 10 puts the
            mask-normalised bar on the errors and the NLL but not on C; averaged over the batch. "mean": the
            mask-normalised mean, like the other terms (about T times weaker; it leaves the priors far from
            the posteriors on short schedules, see the README).
        open_loop_weight: beta >= 0, weight of an extra training term, not in the paper (0, the default, is
            Eq. 10 alone): the accuracy and action terms of Eq. 10 (lambda_v eps_v + lambda_q eps_q +
            lambda_a NLL) again on the exact open-loop rollout of the same episodes, every posterior at its
            prior (Section 3.5; the rollout of `er_iterations=0`). Eq. 10 trains the states regenerated from
            the posteriors, while acting starts every step from the priors; on short CPU schedules the task
            then drifts into the training posteriors and the open-loop chain degrades
            (docs/research/libero_object_cpu.md). This term trains the prior chain itself to follow the
            demonstrations; the CPU recipe `configs/policy/predvla_cpu.json` uses it.
        use_amp: LeRobot's own flag (`--policy.use_amp`, default False: float32, as measured against the paper's
            recipe). True trains with bfloat16 mixed precision: the recurrence's loops and the heads run in bfloat16
            under `lerobot-train`'s autocast, while the losses, the posteriors and both Adams' states stay float32.
            On the CPU a step takes 0.6-0.9x the time, but over 2,000 steps of Table 2's recipe the training-loss
            terms trail float32's by 1-9% (docs/speed.md, "Mixed precision"), so it is opt-in. Error regression and
            the front end always run at full precision, also under `lerobot-eval`'s autocast.
        er_window: Error-regression window W in control steps (Table 2: 40).
        er_iterations: Adam iterations n_itr per control step (Table 2: 10). 0 is exact open loop.
        er_deadline_ms: None (default): every control step runs all `er_iterations`. A value: error regression's
            time budget per control step in milliseconds (e.g. 33 for a 30 Hz robot, minus the front end's share):
            it runs as many of the `er_iterations` as fit, at least one, and logs how many it ran
            (docs/robot.md measures what each budget sustains on 2 CPU cores and what it costs in success: 2 of 10
            iterations succeeded less often than exact open loop).
        er_lr: Adam step size eta of error regression (Table 2: 0.05). With Adam afresh at every control step
            (`er_adam_state="fresh"`) its first iteration moves every posterior coordinate in the window by about
            eta: on a checkpoint whose training posteriors sit closer to their priors than that, error regression
            drives the action head where it was never trained (`predvla inspect` warns and compares step sizes with
            `--er-variant er_lr=...`; docs/research/table2.md: on Table 2's own checkpoint 0.05 does; 0.002 halves
            the action error on replayed demonstrations without more successes in the simulator on the episodes
            evaluated).
        er_adam_state: Whether error regression's Adam starts afresh at every control step ("fresh", the default)
            or each window posterior continues the moments and step count of the control steps it was already
            optimised in ("carried"; the newest starts from zero). Table 2 names Adam but not which; fresh kicks
            every posterior of the window by about `er_lr` at each control step's first iteration, carried only
            the newest (docs/paper.md, "Choices the paper leaves open").
        er_optimizer: Error regression's update of the window's posteriors. "adam" (default, Table 2) or "gd": the
            plain gradient step c_q <- c_q - eta dE/dc_q that Section 3.5 writes, with `er_lr` as eta (no moments;
            `er_adam_state` is then unused).
        er_detach_priors: False (default): dE/dc_q is the full derivative, including how each posterior moves the
            later steps' priors c_p (Eqs. 1-2) through the regenerated states. True: the priors enter the
            complexity term as constants (their values at the current iterate), so the complexity pulls each
            posterior toward its prior and never drags the priors along. Section 3.5 does not say which.
        er_complexity_weight: w_ER, the complexity weight of every module during error regression
            (Table 2: 1.0).
        er_lambda_v: Visual prediction-error weight during error regression (1; 0 is ablation A4).
        er_lambda_q: Proprioceptive prediction-error weight during error regression (1; 0 is A5).
        use_bottleneck: Keep the visual-to-action bottleneck V -> A_top (Eq. 5); False is ablation A2.
        use_efference_copy: Keep the efference copy A -> V of the model's own previous action and
            proprioception predictions (Eq. 6); False is ablation A3.
        recurrence_backend: Implementation of the fused recurrence's per-step loops (forward and hand-written
            BPTT; same results, `tests/test_recurrence_cpp.py`). "auto" (default): the loops compiled in C++
            (`recurrence_cpp.py`) on CPU float32/float64 tensors where a C++ compiler and ninja are present, else the
            Python loops, with one log line saying why. They are compiled once per Python and torch version by
            `predvla build` (`make install` runs it), else by the first rollout (~30 s on 2 cores, logged), and loaded
            in ~0.1 s afterwards. "cpp": the compiled loops or an error naming this flag. "python": ATen ops called
            from Python, on any device and dtype, nothing to build (what configs saved before "auto" existed hold;
            pass `--policy.recurrence_backend=auto` to such a checkpoint for the compiled loops). Error regression on
            CPU is dispatch-bound at batch 1 and runs ~1.6x faster compiled (docs/speed.md).
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
