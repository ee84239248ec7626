"""One training per output folder: an advisory lock the operating system releases when its holder dies.

`lerobot-train` itself lets two trainings write into one `checkpoints/` folder (for instance a resumed run
beside an orphaned trainer that is still alive). The plugin takes `fcntl.flock` on `OUTPUT_DIR/.predvla_train.lock`
for the whole life of the process: a second training on the same folder stops with an error naming the holder
(its pid, host and command, recorded in the file). A process killed in any way, `kill -9` included, releases
the lock with its file descriptors, so a stale file never blocks a resume.
"""

import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path

LOCK_FILE = ".predvla_train.lock"
_held: dict[Path, int] = {}  # output folder -> descriptor, kept open for the life of the process


class OutputDirLockedError(RuntimeError):
    """Another live process trains into the same output folder."""


def holder_description(path: Path) -> str:
    try:
        holder = json.loads(Path(path).read_text())
        return f"pid {holder['pid']} on {holder['host']}, started {holder['started']}: {holder['command']}"
    except (OSError, ValueError, KeyError):
        return "a process that has not yet recorded itself"


def lock_output_dir(output_dir: Path) -> Path:
    """Hold the training lock of `output_dir` (created if needed) until this process ends; returns the lock file.

    Raises `OutputDirLockedError` naming the holder when another live process holds it. Taking it again in the
    process that holds it does nothing.
    """
    output_dir = Path(output_dir).resolve()
    path = output_dir / LOCK_FILE
    if output_dir in _held:
        return path
    output_dir.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise OutputDirLockedError(
            f"{output_dir}: another training holds this output folder ({holder_description(path)}; lock file "
            f"{path}). Wait for it to end or stop it (kill its process group), or pass another --output_dir."
        ) from None
    record = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "command": " ".join(sys.argv)}
    os.ftruncate(fd, 0)
    os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
    _held[output_dir] = fd
    return path
