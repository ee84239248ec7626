"""Fingerprint of scripted-expert hdf5 demonstrations, to tell two regenerations of a dataset apart.

Usage: python fingerprint.py HDF5_SUITE_DIR > fingerprint.json

Per file and demonstration: the first 16 hex digits of the sha256 of its actions, simulator states and each camera's
images, with the machine's CPU and the simulator's version.
"""

import hashlib
import json
import platform
import sys
from pathlib import Path

import h5py
import mujoco
import numpy as np

KEYS = ("actions", "states", "obs/agentview_rgb", "obs/eye_in_hand_rgb")


def digest(array: np.ndarray) -> str:
    return hashlib.sha256(array.tobytes()).hexdigest()[:16]


def cpu_field(name: str) -> str:
    return next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith(name))


def fingerprint(root: Path) -> dict:
    files = {}
    for path in sorted(root.glob("*.hdf5")):
        with h5py.File(path, "r") as f:
            demos = sorted(f["data"], key=lambda name: int(name.split("_")[1]))
            files[path.name] = {d: {k: digest(f[f"data/{d}/{k}"][()]) for k in KEYS} for d in demos}
    machine = {"cpu": cpu_field("model name"), "avx512": sorted(x for x in cpu_field("flags").split() if "avx512" in x),
               "mujoco": mujoco.__version__, "python": platform.python_version()}
    return {"machine": machine, "files": files}


if __name__ == "__main__":
    json.dump(fingerprint(Path(sys.argv[1])), sys.stdout, indent=1)
