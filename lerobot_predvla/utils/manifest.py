"""SHA-256 manifests of checkpoint folders: written with each checkpoint, verified before anything is loaded.

LeRobot's checkpoint format carries no checksum, so a truncated or altered file that still parses would load.
Each folder a checkpoint is made of (`pretrained_model/`, `training_state/`, a `predvla push` commit) carries
`sha256_manifest.json`: the size and SHA-256 of every file in it. `verify_manifest` names the first file that is
missing, of another size (truncated or grown) or of other content (altered). Files the manifest does not list
(added later, e.g. processors LeRobot pushes in their own commits) are not checked. A folder without a manifest
(older checkpoints, other tools) loads as before, with one log line.
"""

import hashlib
import json
import logging
import os
from pathlib import Path

from lerobot_predvla.utils.io import atomic_write_text
from lerobot_predvla.utils.safe_loading import CheckpointError

MANIFEST_FILE = "sha256_manifest.json"
MANIFEST_FORMAT = 1
_CHUNK = 1 << 20


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def listed_files(directory: Path) -> dict[str, Path]:
    """The files a manifest of `directory` covers: every file below it, hidden ones (temporary files of atomic
    writes) and the manifest itself excepted; keyed by their POSIX path relative to `directory`."""
    directory = Path(directory)
    files = {}
    for path in sorted(directory.rglob("*")):
        rel = path.relative_to(directory)
        if path.is_file() and rel.as_posix() != MANIFEST_FILE and not any(p.startswith(".") for p in rel.parts):
            files[rel.as_posix()] = path
    return files


def manifest_text(files: dict[str, Path | bytes]) -> str:
    """The manifest of `files` (relative path -> file on disk or its bytes), as JSON text."""
    entries = {}
    for rel, src in sorted(files.items()):
        if rel == MANIFEST_FILE:
            continue
        if isinstance(src, bytes):
            entries[rel] = {"bytes": len(src), "sha256": sha256_bytes(src)}
        else:
            entries[rel] = {"bytes": Path(src).stat().st_size, "sha256": sha256_file(Path(src))}
    return json.dumps({"format": MANIFEST_FORMAT, "algorithm": "sha256", "files": entries}, indent=2) + "\n"


def write_manifest(directory: Path) -> Path:
    """Write `directory/sha256_manifest.json` (atomically) for the files now in it; returns its path."""
    path = Path(directory) / MANIFEST_FILE
    atomic_write_text(path, manifest_text(listed_files(directory)))
    return path


def read_manifest(directory: Path) -> dict[str, dict] | None:
    """The manifest's entries (relative path -> {"bytes", "sha256"}), or None when the folder has none."""
    path = Path(directory) / MANIFEST_FILE
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
        files = manifest["files"]
        if manifest.get("format") != MANIFEST_FORMAT or not isinstance(files, dict):
            raise ValueError(f"format {manifest.get('format')!r}, expected {MANIFEST_FORMAT}")
    except (ValueError, KeyError, TypeError) as err:
        raise CheckpointError(f"{path}: not a readable manifest (truncated or corrupt?): {err}") from err
    return files


def verify_manifests(*directories: Path) -> bool:
    """Check every file the manifests of `directories` list; True when all were verified.

    Raises `CheckpointError` naming the first file that is missing, truncated or grown, or altered. Folders
    without a manifest are skipped with one log line for all of them.
    """
    unverified = []
    for directory in map(Path, directories):
        entries = read_manifest(directory)
        if entries is None:
            unverified.append(str(directory))
            continue
        for rel, entry in sorted(entries.items()):
            path = directory / rel
            if not path.is_file():
                raise CheckpointError(f"{path}: missing (listed in {directory / MANIFEST_FILE}).")
            size = os.stat(path).st_size
            if size != entry["bytes"]:
                kind = "truncated" if size < entry["bytes"] else "grown"
                raise CheckpointError(f"{path}: {kind}: {size} bytes, the manifest records {entry['bytes']}.")
            if sha256_file(path) != entry["sha256"]:
                raise CheckpointError(f"{path}: altered: its SHA-256 differs from the one in {MANIFEST_FILE}.")
    if unverified:
        logging.info("No %s in %s (a checkpoint saved without one, or another tool's): files not verified.",
                     MANIFEST_FILE, ", ".join(unverified))
    return not unverified
