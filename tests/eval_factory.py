"""A short `lerobot-eval` of the committed libero_object checkpoint in exact open loop (simulator tests)."""

import json
import subprocess
import sys
from pathlib import Path

CHECKPOINT = Path(__file__).parents[1] / "checkpoints" / "predvla_libero_object_reading"


def open_loop_eval(out: Path, task_ids: str, *env_flags: str) -> dict:
    """`lerobot-eval` of `CHECKPOINT` on libero_object's tasks `task_ids` (e.g. "[1,2]"), one 3-step episode each,
    without rendering after reset, with the extra `--env.*` flags; its eval_info.json."""
    command = [str(Path(sys.executable).with_name("lerobot-eval")), f"--policy.path={CHECKPOINT}",
               "--policy.device=cpu", "--policy.er_iterations=0", "--env.type=predvla_libero",
               "--env.task=libero_object", f"--env.task_ids={task_ids}", "--env.episode_length=3",
               "--env.render_interval=100000", *env_flags, "--eval.n_episodes=1",
               "--eval.batch_size=1", "--eval.use_async_envs=false", f"--output_dir={out}"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads((out / "eval_info.json").read_text())
