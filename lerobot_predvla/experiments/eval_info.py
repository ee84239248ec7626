"""Reading `eval_info.json`, the per-task results `lerobot-eval` writes into its output directory."""

import json
from pathlib import Path

EVAL_INFO_FILE = "eval_info.json"


class EvalInfoError(ValueError):
    """A file that is not a lerobot-eval eval_info.json with per-task results."""


def parse_eval_info(path: Path) -> dict[str, dict[str, int]]:
    """Per-task successes, sorted by task id: {task_id: {"successes": s, "episodes": n}}."""
    try:
        info = json.loads(Path(path).read_text())
        tasks = {}
        for entry in info["per_task"]:
            successes = [bool(s) for s in entry["metrics"]["successes"]]
            tasks[str(entry["task_id"])] = {"successes": sum(successes), "episodes": len(successes)}
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise EvalInfoError(f"{path}: not a lerobot-eval {EVAL_INFO_FILE} with per_task successes ({err}).") from err
    if not tasks:
        raise EvalInfoError(f"{path}: no per-task results.")
    return dict(sorted(tasks.items(), key=lambda kv: int(kv[0])))


def success_rates(path: Path) -> dict[int, float]:
    """Success rate (%) per task id."""
    return {int(task): 100.0 * t["successes"] / t["episodes"] for task, t in parse_eval_info(path).items()}
