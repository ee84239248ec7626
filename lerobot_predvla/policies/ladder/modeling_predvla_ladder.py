"""Ladder rungs L2-L5 and side branch L2b (Section 4.6): PredVLA taken apart one mechanism at a time."""

from typing import NamedTuple

import torch
from torch import Tensor, nn

from lerobot_predvla.policies.common.action_head import GMMActionHead, mlp
from lerobot_predvla.policies.common.losses import masked_mean
from lerobot_predvla.policies.common.observation_policy import ObservationPolicy
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import (
    LADDER_PAPER_PARAMETERS,
    LADDER_WIDTHS,
    PredVLALadderConfig,
)
from lerobot_predvla.policies.predvla.modeling_predvla import refresh_mask
from lerobot_predvla.policies.predvla.predictive_model import PredictiveModel, RecurrentState


class LadderCell(nn.Module):
    """One module's update on [d^l_{t-1}; inputs]: leaky tanh with time constant tau (Eqs. 3-4) or an LSTM cell.

    A single bias-ful Linear holds [W_rec | W_in] and b^l (four gates for the LSTM); the initial state (and
    the LSTM's initial cell) is learnable.
    """

    def __init__(self, in_dim: int, dim: int, tau: float, lstm: bool):
        super().__init__()
        self.lstm, self.alpha = lstm, 1.0 / tau
        self.linear = nn.Linear(dim + in_dim, (4 if lstm else 1) * dim)
        self.h0 = nn.Parameter(torch.zeros(dim))
        self.c0 = nn.Parameter(torch.zeros(dim)) if lstm else None

    def initial(self, batch_size: int) -> tuple[Tensor, Tensor | None]:
        return self.h0.expand(batch_size, -1), None if self.c0 is None else self.c0.expand(batch_size, -1)

    def output(self, state: tuple[Tensor, Tensor | None]) -> Tensor:
        """d^l: tanh(h) for the leaky cell (Eq. 3), the hidden output h for the LSTM."""
        return state[0] if self.lstm else torch.tanh(state[0])

    def forward(self, state: tuple[Tensor, Tensor | None], x: Tensor) -> tuple[Tensor, Tensor | None]:
        h, c = state
        pre = self.linear(torch.cat([self.output(state), x], dim=-1))
        if self.lstm:
            i, f, g, o = pre.chunk(4, dim=-1)
            c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
            return torch.sigmoid(o) * torch.tanh(c), c
        return torch.lerp(h, torch.tanh(pre), self.alpha), None


class LadderState(NamedTuple):
    cells: tuple[tuple[Tensor, Tensor | None], ...]  # (h, c) of T, V, A_top, A_bottom
    a_hat: Tensor  # efference copy of the previous action (Eq. 6)
    q_hat: Tensor | None  # and of the previous proprioception output


class ObservationDrivenModel(nn.Module):
    """Rungs L3-L5: PredVLA's hierarchy T -> V -> A_top -> A_bottom with observations as direct inputs."""

    def __init__(self, config: PredVLALadderConfig):
        super().__init__()
        self.config = config
        d_t, d_v, d_at, d_ab = config.module_dims
        lstm = config.rung == "L5"
        efference = config.action_dim + config.proprio_dim if config.use_efference_copy else 0
        bottleneck = config.bottleneck_dim if config.use_bottleneck else 0
        tau = config.tau
        self.cells = nn.ModuleList([
            LadderCell(config.language_dim, d_t, tau[0], lstm),  # T: W_lang l (Eq. 4)
            LadderCell(d_t + config.vision_dim + config.proprio_dim + efference, d_v, tau[1], lstm),  # V: v_t, q_t
            LadderCell(d_t + bottleneck, d_at, tau[2], lstm),  # A_top: W_top z (Eq. 5)
            LadderCell(d_at + config.proprio_dim, d_ab, tau[3], lstm),  # A_bottom: q_t
        ])
        if config.use_bottleneck:
            self.bottleneck_in = nn.Linear(d_v, config.bottleneck_dim, bias=False)  # W_VA (Eq. 5)
        if config.use_efference_copy:
            self.q_head = mlp(d_ab, config.head_hidden_dim, config.proprio_dim)  # source of q_hat (Eq. 6)
        self.action_head = GMMActionHead(
            d_ab, config.head_hidden_dim, config.action_dim, config.num_mixtures, config.min_action_scale
        )

    def _outputs(self, d_ab: Tensor) -> tuple[Tensor, Tensor | None, tuple[Tensor, Tensor, Tensor]]:
        params = self.action_head(d_ab)
        q_hat = self.q_head(d_ab) if self.config.use_efference_copy else None
        return GMMActionHead.mode(params[0], params[1]), q_hat, params

    def initial_state(self, batch_size: int) -> LadderState:
        cells = tuple(cell.initial(batch_size) for cell in self.cells)
        a_hat, q_hat, _ = self._outputs(self.cells[3].output(cells[3]))
        return LadderState(cells, a_hat, q_hat)

    def step(
        self, state: LadderState, language: Tensor, vision: Tensor, proprio: Tensor
    ) -> tuple[LadderState, tuple[Tensor, Tensor, Tensor]]:
        """One control step in module order T, V, A_top, A_bottom; returns the new state and GMM parameters."""
        cfg = self.config
        t_cell, v_cell, at_cell, ab_cell = self.cells
        s_t = t_cell(state.cells[0], language)
        d_t = t_cell.output(s_t)
        v_in = [d_t, vision, proprio]
        if cfg.use_efference_copy:
            v_in += [state.a_hat, state.q_hat]
        s_v = v_cell(state.cells[1], torch.cat(v_in, dim=-1))
        at_in = [d_t, self.bottleneck_in(v_cell.output(s_v))] if cfg.use_bottleneck else [d_t]
        s_at = at_cell(state.cells[2], torch.cat(at_in, dim=-1))
        s_ab = ab_cell(state.cells[3], torch.cat([at_cell.output(s_at), proprio], dim=-1))
        a_hat, q_hat, params = self._outputs(ab_cell.output(s_ab))
        return LadderState((s_t, s_v, s_at, s_ab), a_hat, q_hat), params

    def rollout(self, language: Tensor, vision: Tensor, proprio: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """GMM parameters over time-major sequences (time, batch, ...)."""
        state = self.initial_state(language.shape[0])
        params = []
        for v_t, q_t in zip(vision.unbind(0), proprio.unbind(0), strict=True):  # unbind: see FACTS.md
            state, p = self.step(state, language, v_t, q_t)
            params.append(p)
        return tuple(torch.stack(x) for x in zip(*params, strict=True))


class PredVLALadderPolicy(ObservationPolicy):
    """A rung of the ladder, chosen by `config.rung`; acts without error regression at every rung."""

    config_class = PredVLALadderConfig
    name = "predvla_ladder"

    def __init__(self, config: PredVLALadderConfig, dataset_stats: dict | None = None, dataset_meta=None, **kwargs):
        super().__init__(config, dataset_stats, dataset_meta)
        paper_width = config.width == LADDER_WIDTHS[config.rung]
        self.paper_parameters = LADDER_PAPER_PARAMETERS[config.rung] if paper_width else None
        if config.predictive:
            self.model = PredictiveModel(config)
            if config.rung == "L2b":  # W_vis: direct visual input to A_bottom
                self.visual_input = nn.Linear(config.vision_dim, config.module_dims[3], bias=False)
        else:
            self.model = ObservationDrivenModel(config)
        self.log_parameter_count()
        self.reset()

    def _extra_ab(self, vision: Tensor) -> Tensor | None:
        return self.visual_input(vision) if self.config.rung == "L2b" else None

    def sequence_loss(self, seq: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        cfg, valid = self.config, seq["valid"]
        if not cfg.predictive:
            params = self.model.rollout(seq["language"], seq["vision"], seq["state"])
            nll = masked_mean(-GMMActionHead.distribution(*params).log_prob(seq["action"]), valid)
            return cfg.lambda_a * nll, {"action_nll": nll}
        model, steps = self.model, valid.shape[0]
        # Every posterior equals its prior (c_q=None): no free variables, no complexity term (L2).
        traj = model.rollout(
            model.initial_state(valid.shape[1]), model.language_term(seq["language"]), None,
            extra_ab=self._extra_ab(seq["vision"]), steps=steps,
        )
        fresh = refresh_mask(valid, cfg.visual_refresh_interval)
        eps_v, eps_q = model.prediction_errors(traj, seq["vision"], seq["state"])
        terms = {
            "vision_error": masked_mean(eps_v, fresh),
            "proprio_error": masked_mean(eps_q, valid),
            "action_nll": masked_mean(model.action_nll(traj, seq["action"]), valid),
        }
        loss = cfg.lambda_v * terms["vision_error"] + cfg.lambda_q * terms["proprio_error"]
        return loss + cfg.lambda_a * terms["action_nll"], terms

    def reset(self) -> None:
        super().reset()
        self.state: RecurrentState | LadderState | None = None
        self.lang_term: Tensor | None = None

    def act(self, language: Tensor, vision: Tensor, proprio: Tensor) -> Tensor:
        model = self.model
        if not self.config.predictive:
            if self.state is None:
                self.state = model.initial_state(language.shape[0])
            self.state, _ = model.step(self.state, language, vision, proprio)
            return self.state.a_hat
        if self.state is None:
            self.state, self.lang_term = model.initial_state(language.shape[0]), model.language_term(language)
        self.state = model.step(self.state, self.lang_term, None, self._extra_ab(vision))[0]
        return self.state.a_hat
