"""The Gaussian-mixture action head every policy of the plugin decodes its action with (Section 3.2, Decoders),
and the two-layer decoder it is built on."""

import torch
import torch.nn.functional as F  # noqa: N812
from torch import Tensor, nn
from torch.distributions import Categorical, Independent, MixtureSameFamily, Normal


def mlp(in_dim: int, hidden_dim: int, out_dim: int) -> nn.Sequential:
    """Two-layer decoder head: Linear-ReLU-Linear (Section 3.2, Decoders)."""
    return nn.Sequential(nn.Linear(in_dim, hidden_dim), nn.ReLU(), nn.Linear(hidden_dim, out_dim))


class GMMActionHead(nn.Module):
    """K-component diagonal Gaussian mixture over the action, tanh means, softplus scales + minimum."""

    def __init__(self, in_dim: int, hidden_dim: int, action_dim: int, num_mixtures: int, min_scale: float):
        super().__init__()
        self.action_dim, self.num_mixtures, self.min_scale = action_dim, num_mixtures, min_scale
        self.net = mlp(in_dim, hidden_dim, num_mixtures * (1 + 2 * action_dim))

    def forward(self, d: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        return self.from_hidden(self.net[1](self.net[0](d)))

    def from_hidden(self, hidden: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """GMM parameters from the hidden layer (after its ReLU)."""
        k, a = self.num_mixtures, self.action_dim
        out = self.net[2](hidden)
        logits, means, scales = out.split([k, k * a, k * a], dim=-1)
        means = torch.tanh(means).unflatten(-1, (k, a))
        scales = (F.softplus(scales) + self.min_scale).unflatten(-1, (k, a))
        return logits, means, scales

    @staticmethod
    def distribution(logits: Tensor, means: Tensor, scales: Tensor) -> MixtureSameFamily:
        """The mixture; arguments are not validated, so a non-finite parameter gives a non-finite NLL, which
        the training guard reports with the step and loss terms (docs/reliability.md)."""
        return MixtureSameFamily(
            Categorical(logits=logits, validate_args=False),
            Independent(Normal(means, scales, validate_args=False), 1, validate_args=False),
            validate_args=False,
        )

    @staticmethod
    def mode(logits: Tensor, means: Tensor) -> Tensor:
        """Executed action: the mean of the highest-weight component (Section 3.2)."""
        index = logits.argmax(dim=-1, keepdim=True).unsqueeze(-1).expand(*means.shape[:-2], 1, means.shape[-1])
        return means.gather(-2, index).squeeze(-2)
