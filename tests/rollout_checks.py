"""What the recurrence tests compare between two implementations of `PredictiveModel.rollout`."""

import torch
from torch import Tensor, nn

from lerobot_predvla.policies.predvla.predictive_model import Trajectory


def outputs_and_gradients(traj: Trajectory, model: nn.Module, extra_ab: Tensor, c_q: Tensor | None) -> list[Tensor]:
    """Every output of a rollout, then the gradients of a fixed random projection of them with respect to the
    network, the extra A_bottom input and (when given) the posteriors."""
    outputs = [*traj.d, traj.d_prev_top, traj.q_hat, traj.a_hat, *traj.action_params, *traj.final.h]
    weights = torch.Generator().manual_seed(2)
    scalar = sum((x * torch.randn(x.shape, generator=weights, dtype=x.dtype)).sum() for x in outputs)
    inputs = [*model.parameters(), extra_ab] + ([] if c_q is None else [c_q])
    grads = torch.autograd.grad(scalar, inputs, allow_unused=True)
    return [*outputs, *(torch.zeros(()) if x is None else x for x in grads)]
