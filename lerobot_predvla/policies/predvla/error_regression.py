"""Test-time inference by error regression over a sliding window (Section 3.5).

At each control step: append the observation, initialise the newest posteriors from their priors
(Eqs. 1-2), run `er_iterations` Adam steps on the window's posteriors against the free energy (Eq. 9)
(Adam afresh at every control step, or continuing each posterior's moments: `er_adam_state`; or Section 3.5's
plain gradient step: `er_optimizer="gd"`) with the network
frozen, regenerating the states from the window start after each update, and decode the action from A_bottom.
With zero iterations no observation is ever read: exact open loop.

With a time budget (`er_deadline_ms`), a control step runs as many of the `er_iterations` as fit in the budget
from the step's start, at least one: the next iteration runs only if the mean time of those already run still
fits. The counts are kept (`iterations`) for the policy to log.

Unavailable observations (`ObservationGuard`) arrive as zero rows with an availability flag per environment:
their prediction-error terms are weighted by 0 in the free energy, so they never reach the posteriors or the
state. Should an environment's posteriors still become non-finite, they revert to their values before the
update (its prediction for this step), and `prior_action` holds the open-loop action as a finite fallback.
"""

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import Tensor

from lerobot_predvla.policies.common.action_head import GMMActionHead
from lerobot_predvla.policies.predvla.predictive_model import PredictiveModel, RecurrentState, Trajectory


@contextmanager
def frozen(model: PredictiveModel) -> Iterator[None]:
    """The network is fixed during error regression: no weight gradient is ever formed."""
    flags = [p.requires_grad for p in model.parameters()]
    model.requires_grad_(False)
    try:
        yield
    finally:
        for p, flag in zip(model.parameters(), flags, strict=True):
            p.requires_grad_(flag)


class WindowAdam:
    """`torch.optim.Adam` (default betas and eps, no weight decay) on the window's posteriors, the same
    arithmetic as its single-tensor update, without the optimizer's per-step bookkeeping (hooks, state dicts,
    profiler records), which costs more than the update itself on a window at batch 1.

    Fresh (default): zero moments and one step count for the whole window. Carried (`er_adam_state="carried"`):
    each window row (control step) continues from its own moments and step count, `rows_steps` (window,), so its
    bias correction is Adam's for that row's history; `torch.optim.Adam` run on each row alone takes the same steps.
    """

    def __init__(self, param: Tensor, lr: float, betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8,
                 exp_avg: Tensor | None = None, exp_avg_sq: Tensor | None = None, rows_steps: Tensor | None = None):
        self.param, self.lr, self.betas, self.eps = param, lr, betas, eps
        self.exp_avg = torch.zeros_like(param) if exp_avg is None else exp_avg.clone()
        self.exp_avg_sq = torch.zeros_like(param) if exp_avg_sq is None else exp_avg_sq.clone()
        self.steps = 0
        # Per-row step counts, shaped to broadcast over the row's (batch, latent) entries.
        self.rows_steps = None if rows_steps is None else rows_steps.to(param.dtype).reshape(
            -1, *[1] * (param.dim() - 1))

    @torch.no_grad()
    def step(self, grad: Tensor) -> None:
        beta1, beta2 = self.betas
        self.steps += 1
        self.exp_avg.lerp_(grad, 1 - beta1)
        self.exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
        if self.rows_steps is None:
            bias_correction2_sqrt = (1 - beta2**self.steps) ** 0.5
            denom = (self.exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(self.eps)
            self.param.addcdiv_(self.exp_avg, denom, value=-self.lr / (1 - beta1**self.steps))
            return
        self.rows_steps += 1
        bias_correction2_sqrt = (1 - beta2**self.rows_steps).sqrt()
        denom = (self.exp_avg_sq.sqrt() / bias_correction2_sqrt).add_(self.eps)
        self.param.addcdiv_(self.exp_avg * (-self.lr / (1 - beta1**self.rows_steps)), denom)


@dataclass
class IterationCounts:
    """Adam iterations run per control step (error regression with a time budget runs fewer than configured)."""

    steps: int = 0
    total: int = 0
    fewest: int | None = None
    most: int = 0

    def add(self, iterations: int) -> None:
        self.steps += 1
        self.total += iterations
        self.fewest = iterations if self.fewest is None else min(self.fewest, iterations)
        self.most = max(self.most, iterations)

    def describe(self) -> str:
        return f"{self.total / max(self.steps, 1):.1f} per control step (fewest {self.fewest}, most {self.most})"


class ErrorRegression:
    """Sliding-window posterior inference for a batch of parallel episodes.

    `rollout` defaults to the model's fused `PredictiveModel.rollout`; any callable with its signature fits
    (the benchmarks pass the eager reference).

    `tracer`, when set, is called after every control step with this object, the window's posteriors before
    the step's Adam iterations (None in exact open loop) and the action returned; `predvla trace` sets it to record
    acting in the simulator. It reads and never changes anything.
    """

    tracer: ClassVar[Callable[["ErrorRegression", Tensor | None, Tensor], None] | None] = None

    def __init__(self, model: PredictiveModel, rollout: Callable[..., Trajectory] | None = None):
        self.model = model
        self.config = model.config
        self.rollout = model.rollout if rollout is None else rollout
        # Adam's moments persist across control steps (`er_adam_state="carried"`; plain descent has none).
        self.carries_moments = self.config.er_adam_state == "carried" and self.config.er_optimizer == "adam"
        self.reset()

    def reset(self) -> None:
        self.step_index = 0  # control steps since reset
        self.lang_term: Tensor | None = None
        self.start_state: RecurrentState | None = None  # state before the window's first step
        self.state: RecurrentState | None = None  # state at the newest step
        self.trajectory: Trajectory | None = None  # the window regenerated by the newest `act` (read by tracers)
        self.posteriors: list[Tensor] = []  # one (batch, 4r) tensor per window step
        # er_adam_state="carried": each window step's Adam moments and iterations so far (empty when fresh).
        self.adam_exp_avg: list[Tensor] = []
        self.adam_exp_avg_sq: list[Tensor] = []
        self.adam_steps: list[int] = []
        self.vision: list[Tensor] = []
        self.proprio: list[Tensor] = []
        # Per step, (batch,) weights of the prediction errors: 1 where the observation counts, 0 where it is
        # unavailable or (vision) not a fresh frame.
        self.vision_weight: list[Tensor] = []
        self.proprio_weight: list[Tensor] = []
        self.prior_action: Tensor | None = None  # open-loop action of the newest step
        self.reverted = 0  # environment-steps whose posteriors became non-finite and were reverted
        self.iterations = IterationCounts()

    def free_energy(self, traj: Trajectory, c_q: Tensor) -> Tensor:
        """E over the window (Eq. 9) with the inference weights w_ER, er_lambda_v, er_lambda_q."""
        cfg = self.config
        eps_v, eps_q = self.model.prediction_errors(traj, torch.stack(self.vision), torch.stack(self.proprio))
        w_v, w_q = torch.stack(self.vision_weight), torch.stack(self.proprio_weight)
        priors = self.model.priors(traj)
        if cfg.er_detach_priors:  # the priors as constants of this iterate: C pulls c_q only (`er_detach_priors`)
            priors = priors.detach()
        complexity = self.model.complexity(c_q, priors, (cfg.er_complexity_weight,) * 4)
        return (cfg.er_lambda_v * eps_v * w_v + cfg.er_lambda_q * eps_q * w_q + complexity).sum()

    def __call__(
        self, language: Tensor, vision: Tensor, proprio: Tensor,
        vision_available: Tensor | None = None, proprio_available: Tensor | None = None,
    ) -> Tensor:
        """One control step for a batch; returns the action (batch, action_dim) in normalised units."""
        started = time.perf_counter()
        open_loop_action = self.observe(language, vision, proprio, vision_available, proprio_available)
        if open_loop_action is not None:
            if self.tracer is not None:
                self.tracer(self, None, open_loop_action)
            return open_loop_action
        before = torch.stack(self.posteriors) if self.tracer is not None else None
        self.infer(started)
        action = self.act()
        if self.tracer is not None:
            self.tracer(self, before, action)
        return action

    def observe(
        self, language: Tensor, vision: Tensor, proprio: Tensor,
        vision_available: Tensor | None = None, proprio_available: Tensor | None = None,
    ) -> Tensor | None:
        """Step 1: append the observation; the newest posteriors start at their priors (Eqs. 1-2).

        `vision_available`, `proprio_available` (batch,) bool: False masks that environment's prediction
        error of this step (default: all available). Returns the action directly in exact open loop
        (`er_iterations == 0`), where observations are never stored nor read.
        """
        model, cfg = self.model, self.config
        if self.state is None:
            with torch.no_grad():
                self.lang_term = model.language_term(language)
                self.start_state = self.state = model.initial_state(language.shape[0])
        with torch.no_grad():
            state, params, prior = model.step(self.state, self.lang_term, None)
        fresh = self.step_index % cfg.visual_refresh_interval == 0
        self.step_index += 1
        self.prior_action = GMMActionHead.mode(params[0], params[1])
        if cfg.er_iterations == 0:
            self.state = state
            return self.prior_action
        ones = torch.ones(vision.shape[0], dtype=torch.bool, device=vision.device)
        vision_ok = ones if vision_available is None else vision_available
        proprio_ok = ones if proprio_available is None else proprio_available
        self.posteriors.append(prior)
        if self.carries_moments:
            self.adam_exp_avg.append(torch.zeros_like(prior))
            self.adam_exp_avg_sq.append(torch.zeros_like(prior))
            self.adam_steps.append(0)
        self.vision.append(vision)
        self.proprio.append(proprio)
        self.vision_weight.append((vision_ok & fresh).to(vision.dtype))
        self.proprio_weight.append(proprio_ok.to(proprio.dtype))
        if len(self.posteriors) > cfg.er_window:  # slide: the oldest posterior is final
            with torch.no_grad():
                self.start_state = self.rollout(self.start_state, self.lang_term, self.posteriors[0][None]).final
            for buffer in (self.posteriors, self.vision, self.proprio, self.vision_weight, self.proprio_weight,
                           self.adam_exp_avg, self.adam_exp_avg_sq, self.adam_steps):
                if buffer:
                    del buffer[0]
        return None

    def window_free_energy(self) -> Tensor:
        """Free energy of the window at the current posteriors (no gradient)."""
        with torch.no_grad():
            c_q = torch.stack(self.posteriors)
            return self.free_energy(self.rollout(self.start_state, self.lang_term, c_q), c_q)

    def infer(self, started: float | None = None) -> None:
        """Step 2: n_itr Adam steps on the window's posteriors, network frozen, states regenerated; under
        `er_deadline_ms`, only those that fit in the budget from `started` (default: now), at least one."""
        before = torch.stack(self.posteriors)
        c_q = before.clone().requires_grad_(True)
        plain, carried = self.config.er_optimizer == "gd", self.carries_moments
        adam = None if plain else WindowAdam(c_q, self.config.er_lr, **({
            "exp_avg": torch.stack(self.adam_exp_avg), "exp_avg_sq": torch.stack(self.adam_exp_avg_sq),
            "rows_steps": torch.tensor(self.adam_steps)} if carried else {}))
        budget = self.config.er_deadline_ms
        started = time.perf_counter() if started is None else started
        begin, done = time.perf_counter(), 0
        with frozen(self.model):
            for done in range(1, self.config.er_iterations + 1):
                traj = self.rollout(self.start_state, self.lang_term, c_q)
                (grad,) = torch.autograd.grad(self.free_energy(traj, c_q), c_q)
                if plain:  # Section 3.5 as written: c_q <- c_q - eta dE/dc_q
                    with torch.no_grad():
                        c_q.sub_(grad, alpha=self.config.er_lr)
                else:
                    adam.step(grad)
                now = time.perf_counter()
                if budget is not None and (now - started + (now - begin) / done) * 1e3 > budget:
                    break  # the next iteration would likely end past the budget
        self.iterations.add(done)
        c_q = c_q.detach()
        diverged = ~torch.isfinite(c_q).all(dim=0).all(dim=-1)  # (batch,)
        if bool(diverged.any()):
            self.reverted += int(diverged.sum())
            c_q = torch.where(diverged[None, :, None], before, c_q)
        self.posteriors = list(c_q.unbind(0))
        if carried:  # a reverted environment keeps the moments it had before the step
            keep = diverged[None, :, None]
            self.adam_exp_avg = list(torch.where(keep, torch.stack(self.adam_exp_avg), adam.exp_avg).unbind(0))
            self.adam_exp_avg_sq = list(torch.where(keep, torch.stack(self.adam_exp_avg_sq), adam.exp_avg_sq).unbind(0))
            self.adam_steps = [n + done for n in self.adam_steps]

    def act(self) -> Tensor:
        """Step 3: regenerate the window from the updated posteriors and decode the action from A_bottom."""
        with torch.no_grad():
            traj = self.rollout(self.start_state, self.lang_term, torch.stack(self.posteriors))
        self.trajectory = traj
        self.state = traj.final
        return traj.final.a_hat
