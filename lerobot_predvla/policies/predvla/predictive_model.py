"""The trainable PredVLA network: hierarchical multiple-timescale predictive-coding RNN (Section 3.2).

Modules are evaluated in the order T, V, A_top, A_bottom. Observations never enter this network: it only
generates visual, proprioceptive and action predictions from its posterior free variables c_q and the
language vector. Tensors are time-major: (time, batch, features).
"""

from typing import NamedTuple

import torch
from torch import Tensor, nn

from lerobot_predvla.policies.common.action_head import GMMActionHead, mlp
from lerobot_predvla.policies.predvla import recurrence_cpp
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.recurrence import (
    A_BOTTOM,
    A_TOP,
    FusedWeights,
    Meta,
    T,
    V,
    recurrence,
    shared_acting_chain,
)


def autocast_dtype(device_type: str) -> torch.dtype | None:
    """The dtype of an enclosing `torch.autocast` on `device_type` (LeRobot's `--policy.use_amp`), else None."""
    return torch.get_autocast_dtype(device_type) if torch.is_autocast_enabled(device_type) else None


def cast_floats(tree, dtype: torch.dtype):
    """`tree` (nested tuples, lists and NamedTuples of tensors or None) with every tensor cast to `dtype`;
    the casts are differentiable, so gradients reach the float32 parameters and posteriors in float32."""
    if isinstance(tree, Tensor):
        return tree.to(dtype)
    if tree is None:
        return None
    items = [cast_floats(x, dtype) for x in tree]
    return type(tree)(*items) if hasattr(tree, "_fields") else type(tree)(items)


class RecurrentState(NamedTuple):
    """State carried between control steps: module outputs d^l = tanh(h^l) and efference predictions."""

    h: tuple[Tensor, Tensor, Tensor, Tensor]
    d: tuple[Tensor, Tensor, Tensor, Tensor]
    a_hat: Tensor  # \hat a_{t-1}, the model's own previous action (Eq. 6)
    q_hat: Tensor  # \hat q_{t-1}, the model's own previous proprioception prediction (Eq. 6)

    def detach(self) -> "RecurrentState":
        return RecurrentState(
            tuple(x.detach() for x in self.h), tuple(x.detach() for x in self.d),
            self.a_hat.detach(), self.q_hat.detach(),
        )


class Trajectory(NamedTuple):
    """Outputs of a rollout over a sequence; every field is (time, batch, ...)."""

    d: tuple[Tensor, Tensor, Tensor, Tensor]  # module outputs at each step
    d_prev_top: Tensor  # d^T_{t-1}, input of the root prior (Eq. 2)
    q_hat: Tensor
    a_hat: Tensor
    action_params: tuple[Tensor, Tensor, Tensor]  # GMM logits, means, scales
    final: RecurrentState


class PredictiveModel(nn.Module):
    """Generative dynamics of Eqs. 1-6 with the v, q and action decoders.

    Parameter reading that gives the paper's 675,732 (Table 1): priors are Linear with bias; recurrent,
    top-down, latent (U) and language maps have no bias, plus one bias vector b^l per module; efference
    maps and the 256-32-256 bottleneck have no bias; the v, q and action heads are Linear(256, 256)-ReLU-
    Linear; each module has a learnable initial state.
    """

    def __init__(self, config: PredVLAConfig):
        super().__init__()
        self.config = config
        d_t, d_v, d_at, d_ab = dims = config.module_dims
        r = config.latent_dim
        self.alpha = tuple(1.0 / t for t in config.tau)  # 1 / tau_l (Eqs. 3-4)
        # Eqs. 1-2: priors from d^T_{t-1} (root), d^T_t (V, A_top), d^{A_top}_t (A_bottom).
        self.prior = nn.ModuleList(
            [nn.Linear(d_t, r), nn.Linear(d_t, r), nn.Linear(d_t, r), nn.Linear(d_at, r)]
        )
        # Eqs. 3-4: W_rec, W_td, U and b^l.
        self.rec = nn.ModuleList([nn.Linear(d, d, bias=False) for d in dims])
        self.td = nn.ModuleList(
            [nn.Linear(d_t, d_v, bias=False), nn.Linear(d_t, d_at, bias=False), nn.Linear(d_at, d_ab, bias=False)]
        )
        self.latent = nn.ModuleList([nn.Linear(r, d, bias=False) for d in dims])
        self.bias = nn.ParameterList([nn.Parameter(torch.zeros(d)) for d in dims])
        self.lang = nn.Linear(config.language_dim, d_t, bias=False)  # W_lang (Eq. 4)
        # Eq. 5: visual-to-action bottleneck z = W_VA d^V, beta^{A_top} = W_top z (absent in ablation A2).
        if config.use_bottleneck:
            self.bottleneck_in = nn.Linear(d_v, config.bottleneck_dim, bias=False)
            self.bottleneck_out = nn.Linear(config.bottleneck_dim, d_at, bias=False)
        # Eq. 6: efference copy beta^V = W_ba a_hat_{t-1} + W_bq q_hat_{t-1} (absent in ablation A3).
        if config.use_efference_copy:
            self.efference_a = nn.Linear(config.action_dim, d_v, bias=False)
            self.efference_q = nn.Linear(config.proprio_dim, d_v, bias=False)
        # Decoders.
        self.v_head = mlp(d_v, config.head_hidden_dim, config.vision_dim)
        self.q_head = mlp(d_ab, config.head_hidden_dim, config.proprio_dim)
        self.action_head = GMMActionHead(
            d_ab, config.head_hidden_dim, config.action_dim, config.num_mixtures, config.min_action_scale
        )
        self.h0 = nn.ParameterList([nn.Parameter(torch.zeros(d)) for d in dims])  # learnable initial states

    @property
    def posterior_dim(self) -> int:
        """Size of one step's posterior, all modules concatenated (4 x r)."""
        return 4 * self.config.latent_dim

    def language_term(self, language: Tensor) -> Tensor:
        """W_lang l, constant over an episode (Eq. 4)."""
        return self.lang(language)

    def initial_state(self, batch_size: int) -> RecurrentState:
        h = tuple(h0.expand(batch_size, -1) for h0 in self.h0)
        d = tuple(torch.tanh(x) for x in h)
        q_hat, a_hat = self._efference(d[A_BOTTOM])[:2]
        return RecurrentState(h, d, a_hat, q_hat)

    def _efference(self, d_ab: Tensor) -> tuple[Tensor, Tensor, tuple[Tensor, Tensor, Tensor]]:
        """Proprioceptive prediction, executed action and GMM parameters decoded from A_bottom."""
        params = self.action_head(d_ab)
        return self.q_head(d_ab), GMMActionHead.mode(params[0], params[1]), params

    def _leaky(self, module: int, h: Tensor, pre: Tensor) -> Tensor:
        a = self.alpha[module]
        return (1.0 - a) * h + a * torch.tanh(pre)  # Eqs. 3-4

    def step(
        self, state: RecurrentState, lang_term: Tensor, u: tuple[Tensor, ...] | None, extra_ab: Tensor | None = None
    ) -> tuple[RecurrentState, tuple[Tensor, Tensor, Tensor], Tensor | None]:
        """Advance one control step.

        `u` holds U^l c^l_{q,t} per module. With `u=None` every posterior is set to its prior, computed on
        the fly in module order (error regression's newest step, and exact open loop). `extra_ab`, if given,
        is added to A_bottom's pre-activation. Returns the new state, the GMM parameters and, when `u` was
        None, the posteriors used (= priors).
        """
        (h_t, h_v, h_at, h_ab), (d_t, d_v, d_at, d_ab) = state.h, state.d
        used = []

        def latent(module: int, prior_input: Tensor) -> Tensor:
            if u is not None:
                return u[module]
            c = self.prior[module](prior_input)
            used.append(c)
            return self.latent[module](c)

        h_t = self._leaky(T, h_t, self.rec[T](d_t) + latent(T, d_t) + lang_term + self.bias[T])
        d_t = torch.tanh(h_t)
        pre_v = self.rec[V](d_v) + self.td[0](d_t) + latent(V, d_t) + self.bias[V]
        if self.config.use_efference_copy:
            pre_v = pre_v + self.efference_a(state.a_hat) + self.efference_q(state.q_hat)
        h_v = self._leaky(V, h_v, pre_v)
        d_v = torch.tanh(h_v)
        pre_at = self.rec[A_TOP](d_at) + self.td[1](d_t) + latent(A_TOP, d_t) + self.bias[A_TOP]
        if self.config.use_bottleneck:
            pre_at = pre_at + self.bottleneck_out(self.bottleneck_in(d_v))
        h_at = self._leaky(A_TOP, h_at, pre_at)
        d_at = torch.tanh(h_at)
        pre_ab = self.rec[A_BOTTOM](d_ab) + self.td[2](d_at) + latent(A_BOTTOM, d_at) + self.bias[A_BOTTOM]
        if extra_ab is not None:
            pre_ab = pre_ab + extra_ab
        h_ab = self._leaky(A_BOTTOM, h_ab, pre_ab)
        d_ab = torch.tanh(h_ab)
        q_hat, a_hat, params = self._efference(d_ab)
        new_state = RecurrentState((h_t, h_v, h_at, h_ab), (d_t, d_v, d_at, d_ab), a_hat, q_hat)
        return new_state, params, (torch.cat(used, dim=-1) if u is None else None)

    def fused_weights(self, priors_on_the_fly: bool) -> FusedWeights:
        """Each module's matmuls concatenated along their inputs (see `recurrence`).

        With `priors_on_the_fly` the posterior equals the prior, so U^l c^l = U^l (W_p d + b_p) folds into the
        weight of the prior's input: W_rec^T + U^T W_p^T for the root (Eq. 2), W_td + U W_p otherwise (Eq. 1).
        """
        folded = [self.latent[m].weight @ self.prior[m].weight if priors_on_the_fly else None for m in range(4)]

        def fold(weight: Tensor, m: int) -> Tensor:
            return weight if folded[m] is None else weight + folded[m]

        w_v = [self.rec[V].weight, fold(self.td[0].weight, V)]
        if self.config.use_efference_copy:
            w_v += [self.efference_a.weight, self.efference_q.weight]
        w_at = [self.rec[A_TOP].weight, fold(self.td[1].weight, A_TOP)]
        if self.config.use_bottleneck:
            w_at.append(self.bottleneck_out.weight)
        q_head, action_net = self.q_head, self.action_head.net
        k, a = self.config.num_mixtures, self.config.action_dim
        action_rows = k * (1 + a)  # logits and means; the scales never enter the loop
        return FusedWeights(
            w_t=fold(self.rec[T].weight, T),
            w_v=torch.cat(w_v, dim=1),
            w_at=torch.cat(w_at, dim=1),
            w_va=self.bottleneck_in.weight if self.config.use_bottleneck else None,
            w_ab=torch.cat([self.rec[A_BOTTOM].weight, fold(self.td[2].weight, A_BOTTOM)], dim=1),
            w1=torch.cat([q_head[0].weight, action_net[0].weight]),
            b1=torch.cat([q_head[0].bias, action_net[0].bias]),
            w2=torch.block_diag(q_head[2].weight, action_net[2].weight[:action_rows]),
            b2=torch.cat([q_head[2].bias, action_net[2].bias[:action_rows]]),
        )

    def rollout(
        self, state: RecurrentState, lang_term: Tensor, c_q: Tensor | None = None,
        extra_ab: Tensor | None = None, steps: int | None = None,
    ) -> Trajectory:
        """Regenerate the states over a sequence from posteriors c_q of shape (time, batch, 4r).

        With `c_q=None` every posterior equals its prior, computed on the fly in module order (open loop);
        the length then comes from `extra_ab` or `steps`. `extra_ab` (time, batch, d_A_bottom) is added to
        A_bottom's pre-activation at each step. Same equations as a loop over `step`, fused (`recurrence`; its
        loops compiled in C++ where `config.recurrence_backend` selects them, `recurrence_cpp.loops`).
        """
        length = next(x.shape[0] for x in (c_q, extra_ab) if x is not None) if steps is None else steps
        p = self._pre_activations(state, lang_term, c_q, extra_ab, length)
        meta, inputs, weights, low = self._loop_inputs(state, p, c_q is None)
        # The compiled loops are float32/float64 only: under mixed precision the Python ones run.
        run = recurrence if low is not None else recurrence_cpp.loops(self.config.recurrence_backend, p[T])
        with torch.autocast(p[T].device.type, enabled=False):  # the loops write into preallocated buffers
            outputs = run(meta, *inputs, weights)
        return self._trajectory(state, *(outputs if low is None else cast_floats(outputs, torch.float32)))

    def rollout_shared_acting(
        self, state: RecurrentState, lang_term: Tensor, c_q: Tensor
    ) -> tuple[Trajectory, Trajectory]:
        """`rollout(state, lang_term, c_q)` and `rollout(state, lang_term, c_q.detach())` from one run of the loops
        (`recurrence.SharedActingChain`): the same values and gradients as the two rollouts. The second trajectory
        is for the action term only: its GMM parameters carry their gradient to the network and not to c_q; its
        other fields are the first's, detached. Under mixed precision it is the two rollouts: the shared chain
        splits the priors' gradient by a subtraction, which would cost bfloat16 most of its few digits."""
        if autocast_dtype(c_q.device.type) is not None:
            return self.rollout(state, lang_term, c_q), self.rollout(state, lang_term, c_q.detach())
        p = self._pre_activations(state, lang_term, c_q, None, c_q.shape[0])
        p_act = self._pre_activations(state, lang_term, c_q.detach(), None, c_q.shape[0])
        meta, (p, h, d, a, q), weights, _ = self._loop_inputs(state, p, False)
        kernels = recurrence_cpp.kernels(self.config.recurrence_backend, p[T])
        with torch.autocast(p[T].device.type, enabled=False):
            *outputs, hidden_act = shared_acting_chain(kernels, meta, p, p_act, h, d, a, q, weights)
        traj = self._trajectory(state, *outputs)
        acting = Trajectory(
            d=tuple(x.detach() for x in traj.d), d_prev_top=traj.d_prev_top.detach(), q_hat=traj.q_hat.detach(),
            a_hat=traj.a_hat.detach(), action_params=self.action_head.from_hidden(
                hidden_act[..., self.config.head_hidden_dim :]), final=traj.final.detach(),
        )
        return traj, acting

    def _pre_activations(
        self, state: RecurrentState, lang_term: Tensor, c_q: Tensor | None, extra_ab: Tensor | None, length: int
    ) -> list[Tensor]:
        """Input-independent pre-activation terms for every step: U^l c^l_q + b^l (+ W_lang l) (Eqs. 3-4)."""
        batch = state.h[T].shape[0]
        if c_q is None:
            p = [(self.bias[m] + self.latent[m](self.prior[m].bias)).expand(length, batch, -1) for m in range(4)]
        else:
            per_module = c_q.chunk(4, dim=-1)
            p = [self.latent[m](per_module[m]) + self.bias[m] for m in range(4)]
        p[T] = p[T] + lang_term
        if extra_ab is not None:
            p[A_BOTTOM] = p[A_BOTTOM] + extra_ab
        return p

    def _loop_inputs(self, state: RecurrentState, p: list[Tensor], priors_on_the_fly: bool) -> tuple:
        """The loops' meta, inputs (p, h, d, a, q) and weights, cast to the autocast dtype under mixed precision
        (`--policy.use_amp`: the loops in that dtype, the losses in float32); and that dtype (None: none)."""
        cfg = self.config
        meta = Meta(self.alpha, cfg.use_efference_copy, cfg.num_mixtures, cfg.action_dim, cfg.proprio_dim)
        weights = self.fused_weights(priors_on_the_fly)
        inputs = (p, state.h, state.d, state.a_hat, state.q_hat)
        low = autocast_dtype(p[T].device.type)
        if low is not None:
            inputs, weights = cast_floats((inputs, weights), low)
        return meta, inputs, weights, low

    def _trajectory(
        self, state: RecurrentState, d: list[Tensor], q_hat: Tensor, a_hat: Tensor, hidden: Tensor,
        h_final: tuple[Tensor, ...],
    ) -> Trajectory:
        final = RecurrentState(h_final, tuple(x[-1] for x in d), a_hat[-1], q_hat[-1])
        # Full GMM parameters (for the NLL) batched after the loop from the loop's hidden layer; their mode
        # is the loop's a_hat.
        return Trajectory(
            d=tuple(d),
            d_prev_top=torch.cat([state.d[T][None], d[T][:-1]]),
            q_hat=q_hat,
            a_hat=a_hat,
            action_params=self.action_head.from_hidden(hidden[..., self.config.head_hidden_dim :]),
            final=final,
        )

    def priors(self, traj: Trajectory) -> Tensor:
        """c_p for every step of a trajectory (Eqs. 1-2), (time, batch, 4r)."""
        d_t, _, d_at, _ = traj.d
        return torch.cat(
            [self.prior[T](traj.d_prev_top), self.prior[V](d_t), self.prior[A_TOP](d_t), self.prior[A_BOTTOM](d_at)],
            dim=-1,
        )

    def complexity(self, c_q: Tensor, c_p: Tensor, weights: tuple[float, ...]) -> Tensor:
        """C_t = sum_l w_l 1/2 ||c^l_q - c^l_p||^2 (Eq. 8), per step: (time, batch)."""
        sq = (c_q - c_p).pow(2).unflatten(-1, (4, self.config.latent_dim)).sum(-1)
        return 0.5 * (sq * sq.new_tensor(weights)).sum(-1)

    def prediction_errors(self, traj: Trajectory, vision: Tensor, proprio: Tensor) -> tuple[Tensor, Tensor]:
        """Per-dimension mean squared errors eps_v(t), eps_q(t) (Eq. 7), each (time, batch)."""
        v_hat = self.v_head(traj.d[V])
        return (vision - v_hat).pow(2).mean(-1), (proprio - traj.q_hat).pow(2).mean(-1)

    def action_nll(self, traj: Trajectory, action: Tensor) -> Tensor:
        """Negative log-likelihood of the demonstrated action under the GMM head, (time, batch); in float32 also
        under mixed precision (the heads' matmuls may run in bfloat16, the mixture's log-sum-exp does not)."""
        return -GMMActionHead.distribution(*(x.float() for x in traj.action_params)).log_prob(action.float())
