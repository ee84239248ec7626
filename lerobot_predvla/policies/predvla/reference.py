"""Naive eager reference of the recurrent core: a Python loop over `PredictiveModel.step` (Eqs. 1-6).

This is the implementation the fast path (`lerobot_predvla.policies.predvla.recurrence`) is checked and timed against.
"""

import torch
from torch import Tensor

from lerobot_predvla.policies.predvla.predictive_model import PredictiveModel, RecurrentState, Trajectory


def reference_rollout(
    model: PredictiveModel, state: RecurrentState, lang_term: Tensor, c_q: Tensor | None = None,
    extra_ab: Tensor | None = None, steps: int | None = None,
) -> Trajectory:
    """`PredictiveModel.rollout`'s contract, one eager `step` per control step."""
    length = next(x.shape[0] for x in (c_q, extra_ab) if x is not None) if steps is None else steps
    u_seq: list = [None] * length
    if c_q is not None:
        # U^l c^l_q for all steps at once; `unbind` avoids the T^2 backward of indexing in the loop.
        per_module = c_q.chunk(4, dim=-1)
        u_seq = list(zip(*(model.latent[m](per_module[m]).unbind(0) for m in range(4)), strict=True))
    extra_seq = [None] * length if extra_ab is None else extra_ab.unbind(0)
    d_prev_top, outs, params = [], [], []
    for u, extra in zip(u_seq, extra_seq, strict=True):
        d_prev_top.append(state.d[0])
        state, p, _ = model.step(state, lang_term, u, extra)
        outs.append(state)
        params.append(p)
    return Trajectory(
        d=tuple(torch.stack([s.d[m] for s in outs]) for m in range(4)),
        d_prev_top=torch.stack(d_prev_top),
        q_hat=torch.stack([s.q_hat for s in outs]),
        a_hat=torch.stack([s.a_hat for s in outs]),
        action_params=tuple(torch.stack(x) for x in zip(*params, strict=True)),
        final=state,
    )
