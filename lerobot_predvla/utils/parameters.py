"""Parameter counts of a live module or of saved weights (one definition for logs, sweeps and model cards)."""

from pathlib import Path

from safetensors import safe_open
from torch import nn


def count_parameters(source: nn.Module | Path | str) -> int:
    """Trainable parameters of a module, or every value of a `.safetensors` file (read from its header).

    A saved policy holds only what it trains (frozen encoders live in the front end), so both count the same
    thing for this plugin's checkpoints.
    """
    if isinstance(source, nn.Module):
        return sum(p.numel() for p in source.parameters() if p.requires_grad)
    total = 0
    with safe_open(str(source), framework="pt") as f:
        for key in f.keys():
            n = 1
            for dim in f.get_slice(key).get_shape():
                n *= dim
            total += n
    return total
