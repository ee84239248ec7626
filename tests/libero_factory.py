"""Tiny hdf5 files in the exact original LIBERO layout, and the front-end commands to run on them (tests)."""

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

from lerobot_predvla.cli import convert as convert_cmd
from lerobot_predvla.cli import fit_frontend as fit_frontend_cmd

BIN = Path(sys.executable).parent  # the environment's console scripts: lerobot-train, lerobot-eval, predvla
IMAGE_SIZE = 128
RAW_TOP_ROWS = 4  # Raw (upside-down) images carry a pure red band in their first rows.


def raw_images(num_frames: int, seed: int, size: int = IMAGE_SIZE) -> np.ndarray:
    """Smooth uint8 (N, H, W, 3) frames: a gradient, a moving square and a red band on raw row 0."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size] / size
    base = np.stack([xx, yy, 1 - xx * yy], axis=-1) * rng.uniform(80, 200, 3)
    frames = np.repeat(base[None], num_frames, axis=0)
    side = size // 6
    for t in range(num_frames):
        y, x = (int(v) for v in rng.integers(RAW_TOP_ROWS, size - side, 2))
        frames[t, y : y + side, x : x + side] = rng.uniform(0, 255, 3)
    frames[:, :RAW_TOP_ROWS] = (255, 0, 0)
    return frames.astype(np.uint8)


def write_libero_file(
    path: Path, instruction: str, lengths: list[int], seed: int = 0, size: int = IMAGE_SIZE
) -> dict[str, dict[str, np.ndarray]]:
    """Write `<task>_demo.hdf5` with one demo per length; returns the arrays written per demo."""
    path.parent.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    written = {}
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        data.attrs["env_name"] = "Libero_Tabletop_Manipulation"
        data.attrs["problem_info"] = json.dumps(
            {"problem_name": "libero_tabletop_manipulation", "domain_name": "robosuite",
             "language_instruction": instruction}
        )
        data.attrs["bddl_file_name"] = f"libero/bddl_files/{path.stem}.bddl"
        data.attrs["bddl_file_content"] = "(define (problem LIBERO_Tabletop_Manipulation))"
        data.attrs["env_args"] = json.dumps({"type": 1, "env_name": "Libero_Tabletop_Manipulation"})
        data.attrs["num_demos"] = len(lengths)
        data.attrs["total"] = sum(lengths)
        for i, n in enumerate(lengths):
            demo = data.create_group(f"demo_{i}")
            arrays = {
                "obs/agentview_rgb": raw_images(n, seed * 100 + 2 * i, size),
                "obs/eye_in_hand_rgb": raw_images(n, seed * 100 + 2 * i + 1, size),
                "obs/joint_states": rng.normal(size=(n, 7)),
                "obs/gripper_states": rng.uniform(-0.04, 0.04, size=(n, 2)),
                "obs/ee_states": rng.normal(size=(n, 6)),
                "obs/ee_pos": rng.normal(size=(n, 3)),
                "obs/ee_ori": rng.normal(size=(n, 3)),
                "actions": rng.uniform(-1, 1, size=(n, 7)),
                "states": rng.normal(size=(n, 47)),
                "robot_states": rng.normal(size=(n, 9)),
                "rewards": np.zeros(n, dtype=np.uint8),
                "dones": np.eye(1, n, n - 1, dtype=np.uint8)[0],
            }
            for key, value in arrays.items():
                demo.create_dataset(key, data=value)
            demo.attrs["num_samples"] = n
            demo.attrs["init_state"] = rng.normal(size=47)
            demo.attrs["model_file"] = "<mujoco/>"
            written[f"demo_{i}"] = arrays
    return written


def run(cmd: list[str]) -> str:
    """A console command offline; its output. Fails the test, with the output's end, when it exits non-zero."""
    result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result.stdout + result.stderr


def run_cli(argv: list[str]) -> int:
    """`predvla fit-frontend ...` or `predvla convert ...` in this process; the command's exit code."""
    parser = argparse.ArgumentParser()
    subparsers = parser.add_subparsers()
    fit_frontend_cmd.add_parser(subparsers)
    convert_cmd.add_parser(subparsers)
    args = parser.parse_args(argv)
    return args.func(args)
