"""The original LIBERO demonstration file layout: `<suite>/<task_name>_demo.hdf5`, written atomically."""

import json
import os
from pathlib import Path

import h5py
import numpy as np

from lerobot_predvla.sims.libero.env import TaskSpec, env_kwargs

OBS_KEYS = {  # dataset name -> trailing shape
    "agentview_rgb": (128, 128, 3),
    "eye_in_hand_rgb": (128, 128, 3),
    "joint_states": (7,),
    "gripper_states": (2,),
    "ee_states": (6,),
    "ee_pos": (3,),
    "ee_ori": (3,),
}
DATA_ATTRS = ("env_name", "problem_info", "bddl_file_name", "bddl_file_content", "env_args", "num_demos", "total")
DEMO_ATTRS = ("num_samples", "init_state", "model_file")


def task_file(out: Path, spec: TaskSpec) -> Path:
    return Path(out) / spec.suite / f"{spec.name}_demo.hdf5"


def file_attrs(spec: TaskSpec, env, init_noise: float = 0.0) -> dict[str, str]:
    """`data` attributes as LIBERO's create_dataset.py writes them (paths relative to hf-libero); `init_noise` is the
    arm's initial joint noise the demonstrations were recorded with (`env_kwargs`)."""
    from libero.libero.envs.bddl_utils import get_problem_info
    from robosuite import load_controller_config

    problem_info = get_problem_info(str(spec.bddl_file))
    # The benchmark's instruction (what evaluation gives the policy); a few BDDL texts differ from it.
    problem_info["language_instruction"] = spec.language
    kwargs = {
        **env_kwargs(spec, render=True, init_noise=init_noise),
        "bddl_file_name": spec.bddl_relpath,
        "robots": ["Panda"],
        "controller_configs": load_controller_config(default_controller="OSC_POSE"),
    }
    env_name = type(env.env).__name__
    env_args = {"type": 1, "env_name": env_name, "problem_name": problem_info["problem_name"],
                "bddl_file": spec.bddl_relpath, "env_kwargs": kwargs}
    return {
        "env_name": env_name,
        "problem_info": json.dumps(problem_info),
        "macros_image_convention": "opengl",
        "bddl_file_name": spec.bddl_relpath,
        "bddl_file_content": spec.bddl_file.read_text(),
        "env_args": json.dumps(env_args),
    }


def write_task_file(path: Path, attrs: dict[str, str], demos: list[dict]) -> None:
    """Write demos (dicts with obs arrays, actions, states, robot_states, model_file) via temp + rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with h5py.File(tmp, "w") as f:
        data = f.create_group("data")
        for key, value in attrs.items():
            data.attrs[key] = value
        total = 0
        for i, demo in enumerate(demos):
            n = len(demo["actions"])
            grp = data.create_group(f"demo_{i}")
            for key in OBS_KEYS:
                grp.create_dataset(f"obs/{key}", data=demo[key])
            grp.create_dataset("actions", data=demo["actions"])
            grp.create_dataset("states", data=demo["states"])
            grp.create_dataset("robot_states", data=demo["robot_states"])
            grp.create_dataset("rewards", data=np.eye(1, n, n - 1, dtype=np.uint8)[0])
            grp.create_dataset("dones", data=np.eye(1, n, n - 1, dtype=np.uint8)[0])
            grp.attrs["num_samples"] = n
            grp.attrs["init_state"] = demo["states"][0]
            grp.attrs["model_file"] = demo["model_file"]
            total += n
        data.attrs["num_demos"] = len(demos)
        data.attrs["total"] = total
    os.replace(tmp, path)


def check_task_file(path: Path) -> int:
    """Validate a file against the layout; returns the number of demos, raises ValueError naming the key."""
    with h5py.File(path, "r") as f:
        if "data" not in f:
            raise ValueError(f"{path}: no `data` group")
        data = f["data"]
        for key in DATA_ATTRS:
            if key not in data.attrs:
                raise ValueError(f"{path}: data.attrs[{key!r}] missing")
        if "language_instruction" not in json.loads(data.attrs["problem_info"]):
            raise ValueError(f"{path}: problem_info has no language_instruction")
        demos = sorted(k for k in data if k.startswith("demo_"))
        if len(demos) != data.attrs["num_demos"]:
            raise ValueError(f"{path}: num_demos={data.attrs['num_demos']} but {len(demos)} demo groups")
        total = 0
        for name in demos:
            demo = data[name]
            n = demo["actions"].shape[0]
            expected = {f"obs/{k}": (n, *shape) for k, shape in OBS_KEYS.items()}
            expected |= {"actions": (n, 7), "rewards": (n,), "dones": (n,)}
            for key, shape in expected.items():
                if key not in demo or demo[key].shape != shape:
                    got = demo[key].shape if key in demo else "missing"
                    raise ValueError(f"{path}: {name}/{key} expected shape {shape}, got {got}")
            for key in ("states", "robot_states"):
                if key not in demo or demo[key].shape[0] != n:
                    raise ValueError(f"{path}: {name}/{key} missing or not {n} rows")
            for key in DEMO_ATTRS:
                if key not in demo.attrs:
                    raise ValueError(f"{path}: {name}.attrs[{key!r}] missing")
            if demo.attrs["num_samples"] != n or demo["obs/agentview_rgb"].dtype != np.uint8:
                raise ValueError(f"{path}: {name} num_samples or image dtype wrong")
            total += n
        if total != data.attrs["total"]:
            raise ValueError(f"{path}: total={data.attrs['total']} but demos hold {total} samples")
    return len(demos)
