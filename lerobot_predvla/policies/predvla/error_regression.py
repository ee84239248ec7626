"""Test-time inference by error regression over a sliding window (Section 3.5).

At each control step: append the observation, initialise the newest posteriors from their priors
(Eqs. 1-2), run `er_iterations` Adam steps on the window's posteriors against the free energy (Eq. 9)
with the network frozen, regenerating the states from the window start after each update, and decode
the action from A_bottom. With zero iterations no observation is ever read: exact open loop.
"""

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import torch
from torch import Tensor

from lerobot_predvla.policies.predvla.predictive_model import GMMActionHead, PredictiveModel, RecurrentState, Trajectory


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


class ErrorRegression:
    """Sliding-window posterior inference for a batch of parallel episodes.

    `rollout` defaults to the model's fused `PredictiveModel.rollout`; any callable with its signature fits
    (the benchmarks pass the eager reference).
    """

    def __init__(self, model: PredictiveModel, rollout: Callable[..., Trajectory] | None = None):
        self.model = model
        self.config = model.config
        self.rollout = model.rollout if rollout is None else rollout
        self.reset()

    def reset(self) -> None:
        self.step_index = 0  # control steps since reset
        self.lang_term: Tensor | None = None
        self.start_state: RecurrentState | None = None  # state before the window's first step
        self.state: RecurrentState | None = None  # state at the newest step
        self.posteriors: list[Tensor] = []  # one (batch, 4r) tensor per window step
        self.vision: list[Tensor] = []
        self.proprio: list[Tensor] = []
        self.fresh: list[bool] = []  # whether the step had a fresh visual observation

    def free_energy(self, traj: Trajectory, c_q: Tensor) -> Tensor:
        """E over the window (Eq. 9) with the inference weights w_ER, er_lambda_v, er_lambda_q."""
        cfg = self.config
        eps_v, eps_q = self.model.prediction_errors(traj, torch.stack(self.vision), torch.stack(self.proprio))
        fresh = eps_v.new_tensor(self.fresh)[:, None]
        complexity = self.model.complexity(c_q, self.model.priors(traj), (cfg.er_complexity_weight,) * 4)
        return (cfg.er_lambda_v * eps_v * fresh + cfg.er_lambda_q * eps_q + complexity).sum()

    def __call__(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        """One control step for a batch; returns the action (batch, action_dim) in normalised units."""
        open_loop_action = self.observe(language, vision, proprio)
        if open_loop_action is not None:
            return open_loop_action
        self.infer()
        return self.act()

    def observe(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor | None:
        """Step 1: append the observation; the newest posteriors start at their priors (Eqs. 1-2).

        Returns the action directly in exact open loop (`er_iterations == 0`), where observations are
        never stored nor read.
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
        if cfg.er_iterations == 0:
            self.state = state
            return GMMActionHead.mode(params[0], params[1])
        self.posteriors.append(prior)
        self.vision.append(vision)
        self.proprio.append(proprio)
        self.fresh.append(fresh)
        if len(self.posteriors) > cfg.er_window:  # slide: the oldest posterior is final
            with torch.no_grad():
                self.start_state = self.rollout(self.start_state, self.lang_term, self.posteriors[0][None]).final
            for buffer in (self.posteriors, self.vision, self.proprio, self.fresh):
                del buffer[0]
        return None

    def window_free_energy(self) -> Tensor:
        """Free energy of the window at the current posteriors (no gradient)."""
        with torch.no_grad():
            c_q = torch.stack(self.posteriors)
            return self.free_energy(self.rollout(self.start_state, self.lang_term, c_q), c_q)

    def infer(self) -> None:
        """Step 2: n_itr Adam steps on the window's posteriors, network frozen, states regenerated."""
        c_q = torch.stack(self.posteriors).requires_grad_(True)
        optimizer = torch.optim.Adam([c_q], lr=self.config.er_lr)
        with frozen(self.model):
            for _ in range(self.config.er_iterations):
                traj = self.rollout(self.start_state, self.lang_term, c_q)
                optimizer.zero_grad(set_to_none=True)
                self.free_energy(traj, c_q).backward(inputs=[c_q])
                optimizer.step()
        self.posteriors = list(c_q.detach().unbind(0))

    def act(self) -> Tensor:
        """Step 3: regenerate the window from the updated posteriors and decode the action from A_bottom."""
        with torch.no_grad():
            traj = self.rollout(self.start_state, self.lang_term, torch.stack(self.posteriors))
        self.state = traj.final
        return traj.final.a_hat
