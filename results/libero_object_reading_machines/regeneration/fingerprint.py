"""Fingerprint of scripted-expert hdf5 demonstrations, to tell two regenerations of a dataset apart.

Usage: python fingerprint.py HDF5_SUITE_DIR > fingerprint.json

Per file and demonstration: the first 16 hex digits of the sha256 of its actions, simulator states and each camera's
images, with where it was made (`lerobot_predvla.utils.versions.run_versions`, plus the simulator's version).
"""

import hashlib
import json
import sys
from pathlib import Path

import h5py
import numpy as np

from lerobot_predvla.utils.versions import package_version, run_versions

KEYS = ("actions", "states", "obs/agentview_rgb", "obs/eye_in_hand_rgb")


def digest(array: np.ndarray) -> str:
    return hashlib.sha256(array.tobytes()).hexdigest()[:16]


def fingerprint(root: Path) -> dict:
    files = {}
    for path in sorted(root.glob("*.hdf5")):
        with h5py.File(path, "r") as f:
            demos = sorted(f["data"], key=lambda name: int(name.split("_")[1]))
            files[path.name] = {d: {k: digest(f[f"data/{d}/{k}"][()]) for k in KEYS} for d in demos}
    return {"versions": {**run_versions(), "mujoco": package_version("mujoco")}, "files": files}


if __name__ == "__main__":
    json.dump(fingerprint(Path(sys.argv[1])), sys.stdout, indent=1)
