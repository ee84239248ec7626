"""A small generated LeRobot dataset with PredVLA's cached columns, for tests and the offline demo.

Each task is a smooth, task-specific joint-space motion: proprioception follows damped sinusoids whose
amplitudes and frequencies depend on the task, with a per-episode phase and offset; the action is the
scaled next-step change of the first 7 joints; visual features are a fixed random nonlinear projection
of the state; language features are a fixed random vector per task. It is a stand-in with the converter's
exact columns (`observation.vision_features` 192, `observation.language_features` 64,
`observation.state` 9, `action` 7), not a simulator.
"""

import shutil
from pathlib import Path

import numpy as np
from lerobot.datasets import LeRobotDataset
from tqdm import tqdm

from lerobot_predvla.columns import OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES

FPS = 20


def synthetic_features(vision_dim: int = 192, language_dim: int = 64) -> dict:
    def vector(dim: int, prefix: str) -> dict:
        return {"dtype": "float32", "shape": (dim,), "names": [f"{prefix}_{i}" for i in range(dim)]}

    return {
        OBS_VISION_FEATURES: vector(vision_dim, "v"),
        OBS_LANGUAGE_FEATURES: vector(language_dim, "l"),
        "observation.state": vector(9, "q"),
        "action": vector(7, "a"),
    }


def make_synthetic_dataset(
    root: Path,
    repo_id: str = "local/predvla_synthetic",
    num_tasks: int = 2,
    episodes_per_task: int = 4,
    min_length: int = 40,
    max_length: int = 60,
    seed: int = 0,
    progress: bool = True,
) -> LeRobotDataset:
    """Write the dataset to `root` (replacing nothing: the directory must not exist); `progress` shows a bar."""
    root = Path(root)
    if root.exists():
        raise FileExistsError(f"{root} already exists; choose a new --out directory.")
    rng = np.random.default_rng(seed)
    projection = rng.normal(size=(9, 192)).astype(np.float32)
    languages = rng.normal(size=(num_tasks, 64)).astype(np.float32)
    amplitude = rng.uniform(0.3, 1.0, size=(num_tasks, 9))
    frequency = rng.uniform(0.05, 0.15, size=(num_tasks, 9))
    tmp = root.with_name(f".{root.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    dataset = LeRobotDataset.create(repo_id, FPS, synthetic_features(), root=tmp, use_videos=False)
    episodes = [(task, e) for e in range(episodes_per_task) for task in range(num_tasks)]
    for task, _ in tqdm(episodes, desc="synthetic episodes", disable=not progress):
        length = int(rng.integers(min_length, max_length + 1))
        t = np.arange(length + 1)[:, None]
        phase, offset = rng.normal(0, 0.2, size=9), rng.normal(0, 0.1, size=9)
        q = (offset + amplitude[task] * np.sin(frequency[task] * t + phase) * np.exp(-t / 400)).astype(np.float32)
        action = np.clip((q[1:, :7] - q[:-1, :7]) * 8.0, -1, 1).astype(np.float32)
        vision = np.tanh(q[:-1] @ projection).astype(np.float32)
        for i in range(length):
            dataset.add_frame({
                OBS_VISION_FEATURES: vision[i], OBS_LANGUAGE_FEATURES: languages[task],
                "observation.state": q[i], "action": action[i], "task": f"synthetic task {task}",
            })
        dataset.save_episode()
    dataset.finalize()
    tmp.rename(root)
    return LeRobotDataset(repo_id, root=root)
