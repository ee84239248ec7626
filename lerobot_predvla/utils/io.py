"""Atomic writes: a temporary file beside the target, then a rename, so readers never see half a file."""

import json
import os
from pathlib import Path


def _temporary(path: Path) -> Path:
    """The temporary file beside `path` (its folder created), renamed onto it once written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    path = Path(path)
    tmp = _temporary(path)
    tmp.write_bytes(data)
    os.replace(tmp, path)


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def atomic_write_json(path: Path, data) -> None:
    atomic_write_text(path, json.dumps(data, indent=2) + "\n")


def atomic_save_figure(fig, path: Path, **savefig_kwargs) -> None:
    """A matplotlib figure in the format of `path`'s suffix (e.g. .png); `savefig_kwargs` go to `Figure.savefig`."""
    path = Path(path)
    tmp = _temporary(path)
    fig.savefig(tmp, format=path.suffix.lstrip("."), **savefig_kwargs)
    os.replace(tmp, path)
