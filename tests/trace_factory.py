"""Hand-made `predvla trace` directories and the checkpoint postprocessor they are read with (the tests of
`research.er_correction` and `research.er_timing`)."""

import json
from pathlib import Path

import numpy as np
import torch

from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.common.processors import make_cached_features_pre_post_processors

LOW = np.array([-1.0, -1.0, -0.6, -0.2, -0.7, -0.3, -1.0])
HIGH = np.array([1.0, 1.0, 1.0, 0.5, 0.2, 1.0, 1.0])


def raw_actions(xy: list[tuple[float, float]], close_at: int, steps: int = 12) -> np.ndarray:
    """A raw action sequence whose x, y are `xy` (cycled) and whose gripper closes from step `close_at`."""
    actions = np.zeros((steps, 7))
    actions[:, :2] = [xy[t % len(xy)] for t in range(steps)]
    actions[:, -1] = np.where(np.arange(steps) >= close_at, 1.0, -1.0)
    return actions


def write_trace(directory: Path, checkpoint: Path, episodes: list[np.ndarray], task_id: int = 3,
                open_loop: bool = False, init_states: str = "true", omp_num_threads: str | None = None) -> None:
    """A trace.json as `predvla trace` writes it: actions normalised with the checkpoint's MIN_MAX statistics."""
    directory.mkdir(parents=True)
    args = [f"--policy.path={checkpoint}", f"--env.task_ids=[{task_id}]", f"--env.init_states={init_states}",
            f"--output_dir={directory / 'eval'}"] + (["--policy.er_iterations=0"] if open_loop else [])
    normalised = [(2 * (a - LOW) / (HIGH - LOW) - 1).tolist() for a in episodes]
    trace = {"eval_args": args, "omp_num_threads": omp_num_threads,
             "episodes": [{"steps": list(range(1, len(a) + 1)), "action": a} for a in normalised]}
    (directory / "trace.json").write_text(json.dumps(trace))


def trace_checkpoint(path: Path) -> Path:
    """A checkpoint directory with the postprocessor a PredVLA policy saves (min-max actions)."""
    stats = {"action": {"min": torch.tensor(LOW, dtype=torch.float32), "max": torch.tensor(HIGH, dtype=torch.float32)}}
    _, postprocessor = make_cached_features_pre_post_processors(PredVLAConfig(device="cpu"), stats)
    postprocessor.save_pretrained(path)
    return path
