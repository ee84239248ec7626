"""Checkpoint files read whole and checked before anything is loaded (docs/reliability.md).

A truncated or corrupt `.safetensors` file, one written for another config (missing or extra keys, other
shapes or dtypes) or one holding NaN or infinite values fails with one line naming the file and what does not
match; the module is only written to once every check has passed, so nothing loads half-way. Only
safetensors are read: nothing is ever unpickled.
"""

from pathlib import Path

from safetensors import safe_open
from torch import Tensor

from lerobot_predvla.utils.finite import check_finite


class CheckpointError(ValueError):
    """A checkpoint file that cannot be read or does not match the config."""


def read_safetensors(path: Path | str) -> tuple[dict[str, Tensor], dict[str, str]]:
    """All tensors (on the CPU) and the metadata of a safetensors file."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: missing.")
    try:
        with safe_open(str(path), framework="pt", device="cpu") as f:
            return {key: f.get_tensor(key) for key in f.keys()}, dict(f.metadata() or {})  # noqa: SIM118
    except Exception as err:  # noqa: BLE001  (safetensors reports corruption as several types)
        raise CheckpointError(f"{path}: not a readable safetensors file (truncated or corrupt?): {err}") from err


def _first(keys: list[str]) -> str:
    return str(keys[:3])[:-1] + (", ...]" if len(keys) > 3 else "]")


def check_tensors(path: Path | str, found: dict[str, Tensor], expected: dict[str, Tensor]) -> None:
    """Raise unless `found` has exactly the keys, shapes and dtypes of `expected` and only finite values."""
    missing, unexpected = sorted(set(expected) - set(found)), sorted(set(found) - set(expected))
    if missing or unexpected:
        raise CheckpointError(
            f"{path}: written for another model or config: missing keys {_first(missing)}, unexpected keys "
            f"{_first(unexpected)}."
        )
    for key, reference in expected.items():
        tensor = found[key]
        if tensor.shape != reference.shape or tensor.dtype != reference.dtype:
            raise CheckpointError(
                f"{path}: '{key}' is {tuple(tensor.shape)} {tensor.dtype}, this config needs {tuple(reference.shape)} "
                f"{reference.dtype} (a checkpoint of another config or dataset?)."
            )
    for key, tensor in found.items():
        check_finite(tensor, str(path), key)
