"""Finiteness checks on data that enters PredVLA: converted datasets, checkpoints and front-end artefacts.

One function, `check_finite`, for every source: it names where the array came from, its key and the first
non-finite index, so a bad value is reported once, where it enters, instead of as a NaN loss hours later.
"""

import numpy as np
import torch


class NonFiniteError(ValueError):
    """An array holds NaN or infinite values; the message names its source, key and first bad index."""


def first_nonfinite(array: np.ndarray | torch.Tensor) -> tuple[tuple[int, ...], float] | None:
    """Index and value of the first (row-major) NaN or infinite element, or None if all are finite."""
    if isinstance(array, torch.Tensor):
        array = array.detach().cpu()
        if not array.is_floating_point() or bool(torch.isfinite(array).all()):
            return None
        array = array.float().numpy()
    array = np.asarray(array)
    if not np.issubdtype(array.dtype, np.inexact):
        return None  # integer and boolean arrays cannot hold NaN
    bad = ~np.isfinite(array)
    if not bad.any():
        return None
    index = np.unravel_index(int(np.argmax(bad)), array.shape)
    return tuple(int(i) for i in index), float(array[index])


def check_finite(array: np.ndarray | torch.Tensor, where: str, key: str) -> None:
    """Raise `NonFiniteError` naming `where` (file or dataset, episode), `key` and the first bad index."""
    found = first_nonfinite(array)
    if found is not None:
        index, value = found
        raise NonFiniteError(f"{where}, key '{key}': non-finite value {value} at index {list(index)}.")
