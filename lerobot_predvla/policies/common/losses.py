"""Loss reductions over whole-episode batches, padded past each episode's end (`EpisodeSequences.batch`)."""

from torch import Tensor


def masked_mean(x: Tensor, mask: Tensor) -> Tensor:
    """Mask-normalised mean over the sequence and batch (the overline of Eq. 10)."""
    mask = mask.to(x.dtype)
    return (x * mask).sum() / mask.sum().clamp_min(1.0)
