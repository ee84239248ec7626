"""Where `lerobot-train` puts a run's checkpoints (LeRobot's own directory names), and how they are published.

LeRobot 0.6.1 writes a step's files in place and replaces `checkpoints/last` by unlinking it and creating a
new link, so a kill during the write leaves a half-written step folder and a kill between the two link calls
leaves no `last` to resume from. `save_checkpoint_atomically` and `update_last_checkpoint_atomically` (put in
their place inside `lerobot-train` by `lerobot_predvla.lerobot_integration`) make both atomic:

- the step folder is written whole under a hidden name (`checkpoints/.000004.partial`), with a SHA-256
  manifest in `pretrained_model/` and in `training_state/` (utils/manifest.py), its files flushed to disk,
  and only then renamed to `000004`;
- `last` is replaced by creating the new link under a hidden name and renaming it over the old one.

A kill at any moment leaves `last` pointing at a complete checkpoint (or absent before the first one).
`PREDVLA_KILL_AT=<point>@<step>` kills the process group at a named point of the checkpoint of that step
(`KILL_POINTS`): a deterministic test hook for the fault-injection harness (sweep/kill_resume.py).
"""

import logging
import os
import re
import shutil
import signal
from collections.abc import Callable
from pathlib import Path

from lerobot.utils.constants import CHECKPOINTS_DIR, LAST_CHECKPOINT_LINK, PRETRAINED_MODEL_DIR, TRAINING_STATE_DIR

from lerobot_predvla.utils.manifest import write_manifest

# Written by `predvla sweep` beside a finished training's checkpoints: its training record (command, steps, the
# published model), which model cards read.
TRAIN_DONE_FILE = "predvla_sweep_train.json"

REQUIRED_FILES = ("config.json", "model.safetensors")  # what makes a directory a saved policy
KILL_AT_ENV = "PREDVLA_KILL_AT"
# Named moments of a checkpoint write, in order: inside LeRobot's write (the weights written, the training
# posteriors not yet), the whole step folder staged, the folder published under its step name with `last`
# not yet moved, `last` moved.
KILL_POINTS = ("weights-saved", "staged", "published", "linked")
STAGING_SUFFIX = ".partial"
_RETIRED_SUFFIX = ".retired"
_STEP_FOLDER = re.compile(r"\.?(\d+)(?:\.partial|\.retired)?")


def last_pretrained(output_dir: Path) -> Path:
    """`OUTPUT_DIR/checkpoints/last/pretrained_model`: the latest saved policy of a `lerobot-train` run."""
    return Path(output_dir) / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK / PRETRAINED_MODEL_DIR


def prune_checkpoints(output_dir: Path, keep_every: int) -> list[Path]:
    """Delete a finished run's step folders but every `keep_every`-th step's and the one `last` points to; returns
    what it deleted. Each step folder holds the training posteriors and optimizer state (~300 MB for 500 LIBERO
    demonstrations), so 30 of them fill a disk that the few a run is read at would not."""
    if keep_every < 1:
        raise ValueError(f"keep_every must be >= 1, got {keep_every}.")
    checkpoints = Path(output_dir) / CHECKPOINTS_DIR
    final = (checkpoints / LAST_CHECKPOINT_LINK).resolve()
    removed = []
    for folder in sorted(checkpoints.iterdir()):
        if folder.is_symlink() or not folder.name.isdigit() or folder.resolve() == final:
            continue
        if int(folder.name) % keep_every:
            shutil.rmtree(folder)
            removed.append(folder)
    return removed


def find_pretrained(checkpoint: Path) -> Path | None:
    """The saved policy of `checkpoint`: the directory itself, its `pretrained_model/`, or None."""
    checkpoint = Path(checkpoint)
    for candidate in (checkpoint, checkpoint / PRETRAINED_MODEL_DIR):
        if all((candidate / name).is_file() for name in REQUIRED_FILES):
            return candidate
    return None


def checkpoint_step(directory: Path) -> int | None:
    """The step of the checkpoint `directory` belongs to (a step folder, its staging name or a folder inside)."""
    for path in (Path(directory), *Path(directory).parents):
        match = _STEP_FOLDER.fullmatch(path.name)
        if match and path.parent.name == CHECKPOINTS_DIR:
            return int(match.group(1))
    return None


def kill_point(name: str, directory: Path) -> None:
    """The test hook: SIGKILL this process group if `PREDVLA_KILL_AT` names `name` and the step of `directory`."""
    wanted = os.environ.get(KILL_AT_ENV)
    if not wanted:
        return
    point, _, step = wanted.partition("@")
    if point not in KILL_POINTS or not step.isdigit():
        raise ValueError(f"{KILL_AT_ENV}={wanted!r}: expected <point>@<step> with point one of {list(KILL_POINTS)}.")
    if point == name and checkpoint_step(directory) == int(step):
        logging.warning("%s=%s: killing the process group", KILL_AT_ENV, wanted)
        os.killpg(os.getpgrp(), signal.SIGKILL)


def _fsync_tree(directory: Path) -> None:
    """Flush every file and folder below `directory` to disk (the rename that publishes it comes after)."""
    for root, _, names in os.walk(directory):
        for name in names:
            with open(os.path.join(root, name), "rb") as f:
                os.fsync(f.fileno())
        _fsync_dir(Path(root))


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def remove_leftovers(checkpoints_dir: Path) -> list[Path]:
    """Remove what a killed checkpoint write left in `checkpoints_dir` (staging folders, retired folders, a
    half-made link); call it only while holding the run's lock. Returns what was removed."""
    removed = []
    for path in sorted(Path(checkpoints_dir).glob(".*")):
        if path.name.endswith((STAGING_SUFFIX, _RETIRED_SUFFIX)) and path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.name.startswith(f".{LAST_CHECKPOINT_LINK}.") and path.is_symlink():
            path.unlink()
        else:
            continue
        removed.append(path)
    if removed:
        logging.info("Removed what killed checkpoint writes left: %s", ", ".join(p.name for p in removed))
    return removed


def save_checkpoint_atomically(save_checkpoint: Callable, checkpoint_dir: Path, *args, **kwargs) -> None:
    """LeRobot's `save_checkpoint(checkpoint_dir, ...)`, written under a staging name, given its manifests and
    renamed into place: `checkpoint_dir` is absent or complete at every moment."""
    checkpoint_dir = Path(checkpoint_dir)
    staging = checkpoint_dir.with_name(f".{checkpoint_dir.name}{STAGING_SUFFIX}")
    if staging.exists():
        shutil.rmtree(staging)
    save_checkpoint(staging, *args, **kwargs)
    for part in (PRETRAINED_MODEL_DIR, TRAINING_STATE_DIR):
        if (staging / part).is_dir():
            write_manifest(staging / part)
    _fsync_tree(staging)
    kill_point("staged", staging)
    if checkpoint_dir.exists():  # written by an earlier attempt that was killed before moving `last` to it
        retired = checkpoint_dir.with_name(f".{checkpoint_dir.name}{_RETIRED_SUFFIX}")
        if retired.exists():
            shutil.rmtree(retired)
        checkpoint_dir.rename(retired)
        staging.rename(checkpoint_dir)
        shutil.rmtree(retired)
    else:
        staging.rename(checkpoint_dir)
    _fsync_dir(checkpoint_dir.parent)
    kill_point("published", checkpoint_dir)


def update_last_checkpoint_atomically(checkpoint_dir: Path) -> None:
    """Point `checkpoints/last` at `checkpoint_dir` by renaming a new link over the old one (atomic)."""
    checkpoint_dir = Path(checkpoint_dir)
    last = checkpoint_dir.parent / LAST_CHECKPOINT_LINK
    new = checkpoint_dir.parent / f".{LAST_CHECKPOINT_LINK}.{os.getpid()}"
    if new.is_symlink():
        new.unlink()
    new.symlink_to(checkpoint_dir.name)
    os.replace(new, last)
    _fsync_dir(checkpoint_dir.parent)
    kill_point("linked", checkpoint_dir)
