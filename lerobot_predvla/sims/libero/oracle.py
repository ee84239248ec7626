"""The oracle front end's inputs from LIBERO: object poses relative to the gripper (a diagnostic, `frontend.oracle`).

Live, `predvla_libero` reads them at every step (`--env.oracle=true`); for a demonstration, `demo_object_poses`
replays its saved simulator states. Both read the same LIBERO sensors, so training and evaluation agree.
"""

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from lerobot_predvla.data.libero_hdf5 import DemoRef, read_sim_states
from lerobot_predvla.frontend.oracle import POSE_DIM, OracleStandardisation
from lerobot_predvla.sims.libero.env import TaskSpec, make_env, num_tasks, task_spec

EEF = "robot0_eef"  # LIBERO's sensors name poses in the Panda's end-effector frame `<object>_to_robot0_eef_*`


def objects_of_interest(problem: dict) -> list[str]:
    """The objects of interest (BDDL `:obj_of_interest`) of a parsed LIBERO problem (an env's `parsed_problem`, or
    `robosuite_parse_problem` of its BDDL file) that are movable objects, in BDDL order.

    LIBERO has pose sensors only for movable objects; fixtures and regions of interest are left out.
    """
    movable = {name for names in problem["objects"].values() for name in names}
    names = [name for name in problem["obj_of_interest"] if name in movable]
    if not names:
        raise ValueError(f"the task's objects of interest {problem['obj_of_interest']} include no movable object, "
                         "so the oracle front end has no pose to give.")
    return names


def object_poses(observation: dict, objects: list[str]) -> np.ndarray:
    """(POSE_DIM * len(objects),) float32: per object, its position (m) and the first two columns of its rotation
    matrix in the gripper's frame, from a LIBERO observation's `<object>_to_robot0_eef_pos/quat` (quaternion xyzw)."""
    parts = []
    for name in objects:
        rotation = Rotation.from_quat(observation[f"{name}_to_{EEF}_quat"]).as_matrix()
        parts += [observation[f"{name}_to_{EEF}_pos"], rotation[:, :2].T.ravel()]
    poses = np.concatenate(parts).astype(np.float32)
    assert poses.shape == (POSE_DIM * len(objects),)
    return poses


def file_tasks(suite: str, files: list[Path]) -> dict[Path, TaskSpec]:
    """The task of each demonstration file of a suite (`<task name>_demo.hdf5`), from one reading of its tasks."""
    by_name = {spec.name: spec for spec in (task_spec(suite, task_id) for task_id in range(num_tasks(suite)))}
    tasks = {}
    for path in files:
        name = Path(path).name.removesuffix("_demo.hdf5")
        if name not in by_name:
            raise ValueError(f"{path}: no task of {suite} is named {name!r}, so its scene cannot be rebuilt.")
        tasks[path] = by_name[name]
    return tasks


def demo_object_poses(env, ref: DemoRef, objects: list[str]) -> np.ndarray:
    """(N, POSE_DIM * len(objects)): the oracle's poses at every step of a demonstration, replayed from its saved
    simulator states in `env` (a physics-only env of its task). The states hold every movable object's and the arm's
    pose, so the fixtures' recorded placement (outside the state) does not matter here."""
    return np.stack([object_poses(env.regenerate_obs_from_state(state), objects) for state in read_sim_states(ref)])


def suite_object_poses(suite: str, refs: list[DemoRef]) -> tuple[dict[tuple[Path, str], np.ndarray], dict]:
    """Every demonstration's oracle poses, and the objects of interest per instruction.

    All tasks must have the same number of objects of interest (the feature has one size).
    """
    poses, objects = {}, {}
    by_file: dict[Path, list[DemoRef]] = {}
    for ref in refs:
        by_file.setdefault(ref.file, []).append(ref)
    tasks = file_tasks(suite, list(by_file))
    with tqdm(total=sum(ref.num_frames for ref in refs), desc="oracle poses", unit="frame") as progress:
        for path, file_refs in by_file.items():
            env = make_env(tasks[path])
            env.reset()
            objects[file_refs[0].instruction] = objects_of_interest(env.env.parsed_problem)
            for ref in file_refs:
                poses[(ref.file, ref.demo)] = demo_object_poses(env, ref, objects[ref.instruction])
                progress.update(ref.num_frames)
            env.close()
    sizes = {len(names) for names in objects.values()}
    if len(sizes) != 1:
        raise ValueError(f"the tasks have different numbers of objects of interest ({objects}); the oracle front end "
                         "needs one feature size.")
    return poses, objects


def fit_oracle(suite: str, refs: list[DemoRef]) -> tuple[OracleStandardisation, dict[tuple[Path, str], np.ndarray]]:
    """The oracle's standardisation fitted on every frame of `refs`, and each demonstration's standardised poses."""
    poses, objects = suite_object_poses(suite, refs)
    standardisation = OracleStandardisation.fit(np.concatenate(list(poses.values())), objects)
    return standardisation, {key: standardisation.apply(value) for key, value in poses.items()}

