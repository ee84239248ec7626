"""Reader and validator of the original LIBERO hdf5 demonstrations (`<suite>/<task>_demo.hdf5`).

Every problem is reported as a `LiberoDataError` naming the file, the demonstration and the key.
`scan_suites` validates the structure of all files (shapes, and finite states and actions; no pixel data)
before any work starts.
"""

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from lerobot_predvla.columns import ACTION_DIM, GRIPPER_DIM, HDF5_CAMERAS, JOINT_DIM
from lerobot_predvla.utils.finite import NonFiniteError, check_finite

JOINT_KEY, GRIPPER_KEY, ACTION_KEY = "obs/joint_states", "obs/gripper_states", "actions"
DEMO_FILE_SUFFIX = "_demo.hdf5"
_DEMO_NAME = re.compile(r"demo_(\d+)")


class LiberoDataError(ValueError):
    """Invalid LIBERO input, located by file, demonstration and key."""

    def __init__(self, file: Path | str, message: str, demo: str | None = None, key: str | None = None):
        where = f"{file}" + (f", demo '{demo}'" if demo else "") + (f", key '{key}'" if key else "")
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class DemoRef:
    """A validated demonstration: where it is, its length, instruction and image shapes."""

    file: Path
    demo: str
    num_frames: int
    instruction: str
    image_shapes: tuple[tuple[int, int, int], ...]  # Per camera, in `HDF5_CAMERAS` order.


@dataclass
class LiberoDemo:
    """Arrays of one demonstration. Images are raw hdf5 pixels (upside down), uint8 (N, H, W, 3)."""

    ref: DemoRef
    images: dict[str, np.ndarray]
    state: np.ndarray  # (N, 9) float32: joint_states (7) + gripper_states (2).
    action: np.ndarray  # (N, 7) float32.


def suite_files(hdf5_root: Path | str, suite: str) -> list[Path]:
    """The `*_demo.hdf5` files of a suite, sorted by name."""
    directory = Path(hdf5_root) / suite
    if not directory.is_dir():
        raise LiberoDataError(directory, f"suite directory of '{suite}' does not exist")
    files = sorted(directory.glob(f"*{DEMO_FILE_SUFFIX}"))
    if not files:
        raise LiberoDataError(directory, f"no *{DEMO_FILE_SUFFIX} files in suite '{suite}'")
    return files


def _instruction(path: Path, data: h5py.Group) -> str:
    key = "data.attrs['problem_info']"
    if "problem_info" not in data.attrs:
        raise LiberoDataError(path, "not a LIBERO demonstration file (no problem_info attribute)", key=key)
    try:
        instruction = json.loads(data.attrs["problem_info"])["language_instruction"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise LiberoDataError(path, f"problem_info has no language_instruction ({err!r})", key=key) from err
    if isinstance(instruction, list):  # Some LIBERO files store the instruction as a word list.
        instruction = " ".join(instruction)
    instruction = str(instruction).strip()
    if not instruction:
        raise LiberoDataError(path, "empty language_instruction", key=key)
    return instruction


def _check_demo(path: Path, name: str, group: h5py.Group, instruction: str) -> DemoRef:
    expected = {ACTION_KEY: (ACTION_DIM,), JOINT_KEY: (JOINT_DIM,), GRIPPER_KEY: (GRIPPER_DIM,)}
    lengths = {}
    image_shapes = []
    for key in [ACTION_KEY, JOINT_KEY, GRIPPER_KEY, *(f"obs/{k}" for k in HDF5_CAMERAS.values())]:
        if key not in group:
            raise LiberoDataError(path, "missing key", name, key)
        dataset = group[key]
        if not isinstance(dataset, h5py.Dataset):
            raise LiberoDataError(path, "is a group, expected an array", name, key)
        shape = dataset.shape
        if key in expected:
            if len(shape) != 2 or shape[1:] != expected[key]:
                raise LiberoDataError(path, f"shape {shape}, expected (N, {expected[key][0]})", name, key)
        elif len(shape) != 4 or shape[3] != 3 or dataset.dtype != np.uint8:
            raise LiberoDataError(path, f"shape {shape} {dataset.dtype}, expected uint8 (N, H, W, 3)", name, key)
        else:
            image_shapes.append(tuple(shape[1:]))
        lengths[key] = shape[0]
    num_frames = lengths[ACTION_KEY]
    if num_frames == 0:
        raise LiberoDataError(path, "empty demonstration (0 steps)", name, ACTION_KEY)
    for key, length in lengths.items():
        if length != num_frames:
            raise LiberoDataError(
                path, f"observation/action length mismatch: {length} steps, '{ACTION_KEY}' has {num_frames}",
                name, key,
            )
    for key in expected:  # small arrays: read them now so a NaN stops the conversion before any work
        check_finite(group[key][()], f"{path}, demo '{name}'", key)
    return DemoRef(path, name, num_frames, instruction, tuple(image_shapes))


def scan_file(path: Path | str) -> list[DemoRef]:
    """Validate one LIBERO file's structure and list its demonstrations in numeric order."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            if "data" not in f or not isinstance(f["data"], h5py.Group):
                raise LiberoDataError(path, "not a LIBERO demonstration file (no 'data' group)", key="data")
            data = f["data"]
            instruction = _instruction(path, data)
            names = sorted((n for n in data if _DEMO_NAME.fullmatch(n)), key=lambda n: int(n[5:]))
            if not names:
                raise LiberoDataError(path, "no demonstrations (no data/demo_<i> groups)", key="data")
            return [_check_demo(path, name, data[name], instruction) for name in names]
    except (LiberoDataError, NonFiniteError):
        raise
    except (OSError, RuntimeError, KeyError, ValueError) as err:  # h5py reports corruption as these.
        raise LiberoDataError(path, f"corrupt or unreadable HDF5 file ({err})") from err


def suite_roots(hdf5_roots: Sequence[Path | str], suites: Sequence[str]) -> dict[str, Path]:
    """The root of each suite's folder `<root>/<suite>`: the one of `hdf5_roots` that holds it.

    Several roots let one fit pool suites whose demonstrations were made in different places. A suite found in no
    root or in several, and a root that is missing or holds none of the suites, is an error naming the folders.
    """
    roots = [Path(root) for root in hdf5_roots]
    if not roots or not suites:
        raise ValueError(f"give at least one hdf5 root and one suite, got roots {roots} and suites {list(suites)}.")
    repeated = sorted({suite for suite in suites if list(suites).count(suite) > 1})
    if repeated:
        raise ValueError(f"suites {repeated} are named more than once; each suite's demonstrations are read once.")
    for root in roots:
        if not root.is_dir():
            raise LiberoDataError(root, "hdf5 root does not exist (expected <root>/<suite>/*_demo.hdf5)")
        if len(roots) > 1 and not any((root / suite).is_dir() for suite in suites):
            raise LiberoDataError(root, f"hdf5 root holds none of the suites {list(suites)} (no <root>/<suite> folder)")
    found = {}
    for suite in suites:
        holders = [root for root in roots if (root / suite).is_dir()]
        if not holders:
            raise LiberoDataError(
                roots[0] / suite if len(roots) == 1 else ", ".join(str(root / suite) for root in roots),
                f"suite directory of '{suite}' does not exist",
            )
        if len(holders) > 1:
            raise LiberoDataError(
                ", ".join(str(root / suite) for root in holders),
                f"suite '{suite}' is in several hdf5 roots; give each suite's demonstrations once",
            )
        found[suite] = holders[0]
    return found


def scan_suites(hdf5_roots: Path | str | Sequence[Path | str], suites: Sequence[str]) -> list[DemoRef]:
    """Validate every file of the given suites, each in the one of `hdf5_roots` that holds it (`suite_roots`); all
    demonstrations must share image shapes."""
    roots = [hdf5_roots] if isinstance(hdf5_roots, Path | str) else hdf5_roots
    located = suite_roots(roots, suites)
    refs = [ref for suite in suites for path in suite_files(located[suite], suite) for ref in scan_file(path)]
    first = refs[0]
    for ref in refs:
        if ref.image_shapes != first.image_shapes:
            raise LiberoDataError(
                ref.file, f"image shapes {ref.image_shapes} differ from {first.image_shapes} in {first.file}",
                ref.demo, "obs/" + HDF5_CAMERAS["observation.images.image"],
            )
    return refs


def read_demo(ref: DemoRef, frame_stride: int = 1, cameras: bool = True) -> LiberoDemo:
    """Read one demonstration's arrays (every `frame_stride`-th frame); its images only if `cameras`."""
    key = None
    image_keys = [f"obs/{k}" for k in HDF5_CAMERAS.values()] if cameras else []
    try:
        with h5py.File(ref.file, "r") as f:
            group = f["data"][ref.demo]
            arrays = {}
            for key in [ACTION_KEY, JOINT_KEY, GRIPPER_KEY, *image_keys]:
                arrays[key] = group[key][::frame_stride]
    except (OSError, RuntimeError, KeyError, ValueError) as err:
        raise LiberoDataError(ref.file, f"cannot read data ({err})", ref.demo, key) from err
    state = np.concatenate([arrays[JOINT_KEY], arrays[GRIPPER_KEY]], axis=1).astype(np.float32)
    images = {camera: arrays[f"obs/{k}"] for camera, k in HDF5_CAMERAS.items() if f"obs/{k}" in arrays}
    return LiberoDemo(ref, images, state, arrays[ACTION_KEY].astype(np.float32))


def read_sim_states(ref: DemoRef) -> np.ndarray:
    """One demonstration's flattened simulator states (N, S), each before its step's action."""
    try:
        with h5py.File(ref.file, "r") as f:
            states = f["data"][ref.demo]["states"][()]
    except (OSError, RuntimeError, KeyError, ValueError) as err:
        raise LiberoDataError(ref.file, f"cannot read the simulator states ({err})", ref.demo, "states") from err
    if states.ndim != 2 or len(states) != ref.num_frames:
        raise LiberoDataError(ref.file, f"shape {states.shape}, expected ({ref.num_frames}, S)", ref.demo, "states")
    return states
