"""PredVLA policy for LeRobot: training with per-episode posteriors (Eq. 10), acting by error regression."""

import logging
import time
from pathlib import Path
from typing import ClassVar, Protocol

import torch
from huggingface_hub import ModelCard
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.utils.constants import TRAINING_STATE_DIR
from torch import Tensor

from lerobot_predvla.policies.common.cached_features import (
    feature_layout,
    has_paper_layout,
    use_dataset_frontend,
)
from lerobot_predvla.policies.common.losses import masked_mean
from lerobot_predvla.policies.common.observation_guard import REPORT_INTERVAL_S, ObservationGuard
from lerobot_predvla.policies.common.sequence_table import EpisodeSequences
from lerobot_predvla.policies.common.training_guard import TrainingGuard
from lerobot_predvla.policies.predvla.configuration_predvla import PREDVLA_PAPER_PARAMETERS, PredVLAConfig
from lerobot_predvla.policies.predvla.corruption import ObservationCorruption
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression
from lerobot_predvla.policies.predvla.posterior_store import PosteriorStore
from lerobot_predvla.policies.predvla.predictive_model import PredictiveModel
from lerobot_predvla.policies.predvla.recurrence_cpp import auto_uses_cpp
from lerobot_predvla.utils.checkpoints import kill_point
from lerobot_predvla.utils.manifest import verify_manifests
from lerobot_predvla.utils.safe_loading import check_tensors, read_safetensors
from lerobot_predvla.utils.threads import acting_threads

# Without `posteriors_fit_actions` the action term's chain shares the posterior chain's forward
# (`PredictiveModel.rollout_shared_acting`): the same losses and gradients as rolling it out again, which False does
# (benchmarks and the test that compares the two).
SHARED_ACTING_CHAIN = True


def training_complexity(complexity: Tensor, mask: Tensor, reduction: str) -> Tensor:
    """C of Eq. 10 from the per-step C_t (time, batch): Eq. 10 puts no bar on C, so by default ("sum") it is
    summed over each sequence's valid steps as in Eq. 9 and averaged over the batch; "mean" is the bar."""
    if reduction == "mean":
        return masked_mean(complexity, mask)
    return (complexity * mask.to(complexity.dtype)).sum() / mask.shape[1]


def refresh_mask(valid: Tensor, interval: int) -> Tensor:
    """Valid steps that bring a fresh visual observation (Section 4: eps_v only on refresh steps), (time, batch)."""
    steps = torch.arange(valid.shape[0], device=valid.device)[:, None]
    return valid & (steps % interval == 0)


def training_terms(model: PredictiveModel, cfg: PredVLAConfig, seq: dict[str, Tensor], c_q: Tensor,
                   lang_term: Tensor) -> dict[str, Tensor]:
    """The four terms of Eq. 10 (unweighted) on the rollout driven by the posteriors c_q (time, batch, 4r) of the
    sequences `seq` (`EpisodeSequences.batch`). Without `cfg.posteriors_fit_actions` the action term comes from the
    same rollout with c_q detached: the same value, no gradient into the posteriors."""
    valid = seq["valid"]
    start = model.initial_state(valid.shape[1])
    if cfg.posteriors_fit_actions:
        traj = acting = model.rollout(start, lang_term, c_q)
    elif SHARED_ACTING_CHAIN:
        traj, acting = model.rollout_shared_acting(start, lang_term, c_q)
    else:
        traj, acting = model.rollout(start, lang_term, c_q), model.rollout(start, lang_term, c_q.detach())
    eps_v, eps_q = model.prediction_errors(traj, seq["vision"], seq["state"])
    complexity = model.complexity(c_q, model.priors(traj), cfg.complexity_weights)
    return {
        "vision_error": masked_mean(eps_v, refresh_mask(valid, cfg.visual_refresh_interval)),
        "proprio_error": masked_mean(eps_q, valid),
        "action_nll": masked_mean(model.action_nll(acting, seq["action"]), valid),
        "complexity": training_complexity(complexity, valid, cfg.complexity_reduction),
    }


def trim_padding(seq: dict[str, Tensor], c_q: Tensor) -> tuple[dict[str, Tensor], Tensor]:
    """The batch cut after its longest episode's last valid step. Every term of Eq. 10 is masked there and a
    posterior only reaches later steps, so the losses and every gradient are those of the padded batch, without
    running the recurrence over steps that no episode of the batch has."""
    valid = seq["valid"]
    length = int(valid.any(dim=1).nonzero().max()) + 1 if bool(valid.any()) else valid.shape[0]
    if length == valid.shape[0]:
        return seq, c_q
    return {k: v if k == "language" else v[:length] for k, v in seq.items()}, c_q[:length]


def term_weights(cfg: PredVLAConfig) -> dict[str, float]:
    """The weights of Eq. 10's terms: lambda_v, lambda_q, lambda_a and 1 for C (its w_l are inside it)."""
    return {"vision_error": cfg.lambda_v, "proprio_error": cfg.lambda_q, "action_nll": cfg.lambda_a,
            "complexity": 1.0}


class Publishing(Protocol):
    """The Hub code behind LeRobot's publishing methods of the policy (`push_model_to_hub`, `push_to_hub`,
    `generate_model_card`): `lerobot_predvla.hub.upload`. The hub sits above every policy (the card has each policy
    type's section), so the policy never imports it: the package's registration (`lerobot_predvla/__init__.py`),
    which every import of the plugin runs first, sets `PredVLAPolicy.publishing` to it."""

    def push_policy(self, policy: PreTrainedPolicy, repo_id: str, *, cfg=None, state_dict=None, dataset_meta=None,
                    private: bool | None = None) -> str: ...

    def policy_card(self, policy: PreTrainedPolicy, repo_id: str, *, cfg=None, dataset_meta=None) -> str: ...


class PredVLAPolicy(PreTrainedPolicy):
    """PredVLA: language-conditioned predictive-coding policy (paper Section 3).

    Built by `lerobot-train` with the dataset's metadata, it holds the training posteriors of every
    episode (`posterior_store`) and the episodes' cached feature columns in memory. Built from a
    checkpoint for evaluation, it holds only the network (675,732 parameters at the paper's LIBERO layout; the
    sizes of the inputs and the action follow the dataset's features).
    """

    config_class = PredVLAConfig
    name = "predvla"
    publishing: ClassVar[Publishing]  # hub/upload.py, handed over by the package's registration (see Publishing)

    def __init__(self, config: PredVLAConfig, dataset_stats: dict | None = None, dataset_meta=None, **kwargs):
        super().__init__(config)
        config.validate_features()
        self.config = config
        self.model = PredictiveModel(config)
        if config.recurrence_backend == "auto" and torch.device(config.device).type == "cpu":
            auto_uses_cpp()  # build or load the compiled loops now (once per Python and torch), not at the first tick
        if config.flush_denormal and torch.device(config.device).type == "cpu":
            torch.set_flush_denormal(True)  # subnormal weights slow late training on x86 (`flush_denormal`)
        count = sum(p.numel() for p in self.network_parameters())
        paper = f"; Table 1: {PREDVLA_PAPER_PARAMETERS:,}" if has_paper_layout(config) else ""
        logging.info("PredVLA: %s trainable parameters (%s%s)", f"{count:,}", feature_layout(config), paper)
        self.sequences: EpisodeSequences | None = None
        self.posterior_store: PosteriorStore | None = None
        if dataset_meta is not None:
            use_dataset_frontend(config, Path(dataset_meta.root))
            self.train_on(EpisodeSequences.from_dataset(Path(dataset_meta.root), config, dataset_stats))
        self._write_posteriors = True
        self.corruption = ObservationCorruption.from_config(config)  # Section 4.4; None unless configured
        self.training_guard = TrainingGuard(
            self, config.on_nonfinite_training, self.name,
            extra=self.posterior_store.pending_gradients if self.posterior_store is not None else None,
        )
        self.reset()

    def train_on(self, sequences: EpisodeSequences) -> None:
        """Hold the training episodes and one posterior per episode, step and module (Section 3.4), in a store
        stepped by its own Adam (`posterior_store.py`; Table 2's posterior learning rate, the optimizer preset's
        betas and eps). `lerobot-train` calls it through the constructor's `dataset_meta`."""
        config, adam = self.config, self.config.get_optimizer_preset()
        self.sequences = sequences
        self.posterior_store = PosteriorStore(
            sequences.vision.shape[0], config.sequence_length, self.model.posterior_dim,
            lr=config.posterior_lr, betas=adam.betas, eps=adam.eps, moments_dtype=config.posterior_moments_dtype,
            dense=config.posterior_adam == "dense",
        )
        # DDP must neither broadcast the store nor all-reduce it: `PosteriorStore.step` exchanges the batch's
        # rows only (torch.nn.parallel.DistributedDataParallel reads this attribute of the wrapped module).
        self._ddp_params_and_buffers_to_ignore = [f"posterior_store.{n}" for n, _ in
                                                  self.posterior_store.named_buffers()]

    # ----- parameters, saving, loading -------------------------------------------------------------
    def network_parameters(self) -> list[torch.nn.Parameter]:
        """The trainable controller (Table 1: 675,732 parameters), posteriors excluded."""
        return list(self.model.parameters())

    def get_optim_params(self) -> list[dict]:
        """The network's weights; lr and weight decay from the optimizer preset. The training posteriors are
        stepped by `update`, row by row (posterior_store.py)."""
        return [{"params": self.network_parameters()}]

    def update(self) -> None:
        """Adam on the training posteriors of the batch just trained on (Section 3.4).

        `lerobot-train` calls it after every optimizer step; a hand-written loop calls it after
        `optimizer.step()` too. Gradients accumulated over several forward/backward passes are applied together.
        """
        if self.posterior_store is not None:
            self.posterior_store.step()

    def _save_pretrained(self, save_directory: Path, state_dict: dict[str, Tensor] | None = None) -> None:
        super()._save_pretrained(save_directory, state_dict=state_dict)
        kill_point("weights-saved", Path(save_directory))  # test hook of the kill-resume harness; inert otherwise
        if self.posterior_store is not None and self._write_posteriors:
            self.posterior_store.save(Path(save_directory))  # training checkpoints only; see push_model_to_hub

    def push_model_to_hub(self, cfg, peft_model=None, state_dict=None, dataset_meta=None) -> str:
        """`lerobot-train --policy.push_to_hub=true`: network, train config, front end and PredVLA's own card
        (`hub/predvla_card.md`), never the training posteriors. LeRobot pushes the processors afterwards."""
        if peft_model is not None:
            raise NotImplementedError("PredVLA is trained in full; --policy.use_peft is not supported.")
        return self._without_posteriors(
            self.publishing.push_policy, self, self.config.repo_id, cfg=cfg, state_dict=state_dict,
            dataset_meta=dataset_meta, private=self.config.private,
        )

    def push_to_hub(self, repo_id: str, *, private: bool | None = None, card_kwargs: dict | None = None) -> str:
        """Publish this policy (network, config, PredVLA card; no posteriors) to `repo_id`."""
        if card_kwargs:
            raise ValueError("PredVLA's model card is rendered from hub/predvla_card.md; card_kwargs are not used.")
        return self._without_posteriors(self.publishing.push_policy, self, repo_id, private=private)

    def generate_model_card(
        self, dataset_repo_id=None, model_type=None, license=None, tags=None, cfg=None, dataset_meta=None
    ) -> ModelCard:
        """PredVLA's card (`hub/predvla_card.md`) instead of LeRobot's generic one (same signature)."""
        return ModelCard(self._without_posteriors(
            self.publishing.policy_card, self, self.config.repo_id or "local", cfg=cfg, dataset_meta=dataset_meta))

    def _without_posteriors(self, fn, *args, **kwargs):
        self._write_posteriors = False  # the Hub gets the controller, never the training posteriors
        try:
            return fn(*args, **kwargs)
        finally:
            self._write_posteriors = True

    @classmethod
    def _load_as_safetensor(cls, model: "PredVLAPolicy", model_file: str, map_location: str, strict: bool):
        """Weights (and, resuming training, posteriors) read and checked whole before either is loaded, after the
        checkpoint's SHA-256 manifests: `pretrained_model/` and, resuming, the `training_state/` LeRobot reads next."""
        directory = Path(model_file).parent
        training_state = directory.parent / TRAINING_STATE_DIR
        resuming = model.posterior_store is not None and training_state.is_dir()
        verify_manifests(directory, *([training_state] if resuming else []))
        state, _ = read_safetensors(model_file)
        check_tensors(model_file, state, {k: v.detach().cpu() for k, v in model.state_dict().items()})
        posteriors = None
        if model.posterior_store is not None:  # resuming training: restore posteriors, moments and step counts
            posteriors = model.posterior_store.read(Path(model_file).parent)
        model.load_state_dict(state)
        if posteriors is not None:
            model.posterior_store.assign(posteriors)
        return model

    # ----- training ------------------------------------------------------------------------------------
    def forward(self, batch: dict[str, Tensor], reduction: str = "mean") -> tuple[Tensor, dict]:
        """Training loss of Eq. 10 on whole episodes of the batch's `episode_index`."""
        if reduction != "mean":
            raise NotImplementedError(
                f"PredVLA's loss is a mask-normalised mean over whole episodes (Eq. 10); reduction={reduction!r} "
                "(per-sample weighting in lerobot-train) is not supported."
            )
        if self.sequences is None or self.posterior_store is None:
            raise RuntimeError(
                "PredVLAPolicy.forward needs the training dataset: build the policy with `dataset_meta` "
                "(lerobot-train does) so that episodes and posteriors are available."
            )
        cfg = self.config
        episode_index = batch["episode_index"].reshape(-1)
        seq = self.sequences.batch(episode_index, self.posterior_store.latents.device)
        c_q = self.posterior_store.gather(episode_index.to(self.posterior_store.latents.device))
        seq, c_q = trim_padding(seq, c_q)
        model = self.model
        lang_term = model.language_term(seq["language"])
        terms = training_terms(model, cfg, seq, c_q, lang_term)
        loss = sum(weight * terms[name] for name, weight in term_weights(cfg).items())
        valid = seq["valid"]
        if cfg.open_loop_weight > 0.0:  # the same accuracy and action terms on the exact open-loop chain
            fresh = refresh_mask(valid, cfg.visual_refresh_interval)
            open_loop = model.rollout(model.initial_state(len(episode_index)), lang_term, steps=valid.shape[0])
            eps_v, eps_q = model.prediction_errors(open_loop, seq["vision"], seq["state"])
            terms["open_loop_vision_error"] = masked_mean(eps_v, fresh)
            terms["open_loop_proprio_error"] = masked_mean(eps_q, valid)
            terms["open_loop_action_nll"] = masked_mean(model.action_nll(open_loop, seq["action"]), valid)
            loss = loss + cfg.open_loop_weight * (
                cfg.lambda_v * terms["open_loop_vision_error"] + cfg.lambda_q * terms["open_loop_proprio_error"]
                + cfg.lambda_a * terms["open_loop_action_nll"]
            )
        values = {k: v.item() for k, v in terms.items()}
        return self.training_guard.check_loss(loss, values), values

    # ----- acting --------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Clear the error-regression window (called at every environment reset); log the finished episode's
        unavailable observations, if any, and (under `er_deadline_ms`) the iterations it ran."""
        if getattr(self, "error_regression", None) is not None and self.error_regression.iterations.steps:
            self.log_iterations()
        self.error_regression = ErrorRegression(self.model)
        self.iterations_logged_at = time.monotonic()
        self.control_step = 0
        if not hasattr(self, "guard"):
            self.guard = ObservationGuard.for_policy(self.config, self.name)
        self.guard.reset()

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        return self.select_action(batch)[:, None]

    def select_action(self, batch: dict[str, Tensor], **kwargs) -> Tensor:
        """One control step of error regression; works under lerobot-eval's `torch.inference_mode()`.

        A missing or non-finite vision or proprio row is masked out of that environment's free energy
        (`on_bad_observation`); the returned action is always finite.
        """
        if self.corruption is not None:  # the corrupted observation is what error regression sees
            batch = self.corruption(self.control_step, batch)
        self.control_step += 1
        (language, vision, proprio), (_, vision_ok, proprio_ok) = self.guard(batch)
        # Error regression runs in float32 also under `--policy.use_amp` (lerobot-eval's autocast): at batch 1 its
        # matmuls are slower in bfloat16 on CPU, and its Adam steps on the window are small. On the CPU it runs on
        # one thread unless OMP_NUM_THREADS is set (utils/threads.py).
        with torch.inference_mode(False), torch.enable_grad(), torch.autocast(vision.device.type, enabled=False), \
                acting_threads(vision.device):
            # Inputs created in inference mode cannot enter autograd: clone them out of it.
            inputs = [x.clone() for x in (language, vision, proprio, vision_ok, proprio_ok)]
            action = self.error_regression(*inputs).detach()
            if time.monotonic() - self.iterations_logged_at >= REPORT_INTERVAL_S:
                self.log_iterations()
            return self.guard.safe_action(action, self.error_regression.prior_action.detach())

    def log_iterations(self) -> None:
        """Under `er_deadline_ms`, one line: the Adam iterations error regression ran per control step so far."""
        self.iterations_logged_at = time.monotonic()
        if self.config.er_deadline_ms is not None:
            logging.info(
                "%s: error regression within %g ms ran %s of %d iterations over %d control steps.", self.name,
                self.config.er_deadline_ms, self.error_regression.iterations.describe(), self.config.er_iterations,
                self.error_regression.iterations.steps,
            )

