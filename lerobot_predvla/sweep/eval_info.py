"""Reading `eval_info.json`, the per-task results `lerobot-eval` writes into its output directory."""

import json
from pathlib import Path

from lerobot_predvla.utils.statistics import task_rates

EVAL_INFO_FILE = "eval_info.json"


class EvalInfoError(ValueError):
    """A file that is not a lerobot-eval eval_info.json with per-task results."""


def episode_successes(path: Path) -> dict[str, list[bool]]:
    """Success of every episode per task, sorted by task id: {task_id: [episode 0, episode 1, ...]}."""
    try:
        info = json.loads(Path(path).read_text())
        tasks = {str(entry["task_id"]): [bool(s) for s in entry["metrics"]["successes"]] for entry in info["per_task"]}
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise EvalInfoError(f"{path}: not a lerobot-eval {EVAL_INFO_FILE} with per_task successes ({err}).") from err
    if not tasks:
        raise EvalInfoError(f"{path}: no per-task results.")
    return dict(sorted(tasks.items(), key=lambda kv: int(kv[0])))


def unsettled_episodes(path: Path) -> dict[str, list[int]]:
    """Per task id, the indices of the episodes whose shifted bodies did not settle where they were put
    (`predvla_shifts.unsettled_episodes`, written by `predvla_libero` with `--env.object_shift_cm` or
    `--env.placement_spread_cm`; an index is the episode's place in the task's `successes`); empty without shifts."""
    try:
        shifts = json.loads(Path(path).read_text()).get("predvla_shifts") or {}
        unsettled: dict[str, list[int]] = {}
        for episode in shifts.get("unsettled_episodes", []):
            unsettled.setdefault(str(episode["task_id"]), []).append(int(episode["episode_ix"]))
    except (OSError, ValueError, AttributeError, KeyError, TypeError) as err:
        raise EvalInfoError(f"{path}: unreadable {EVAL_INFO_FILE} ({err}).") from err
    return {task: sorted(set(episodes)) for task, episodes in sorted(unsettled.items(), key=lambda kv: int(kv[0]))}


def recorded_unsettled(record: dict) -> dict[str, list[int]] | None:
    """Per task id, the unsettled episodes' indices that a run record of shifted objects keeps
    (`shift_unsettled_episodes`); a record written before it kept them has only their count (`shift_unsettled`),
    which tells them only when it is 0. None when they are not known."""
    if record.get("shift_unsettled_episodes") is not None:
        return {str(task): [int(i) for i in episodes] for task, episodes in record["shift_unsettled_episodes"].items()}
    if record.get("shift_unsettled") == 0:
        return {str(task): [] for task in record.get("tasks", {})}
    return None


def parse_eval_info(path: Path) -> dict[str, dict[str, int]]:
    """Per-task successes, sorted by task id: {task_id: {"successes": s, "episodes": n}}."""
    return {task: {"successes": sum(s), "episodes": len(s)} for task, s in episode_successes(path).items()}


def success_rates(path: Path) -> dict[int, float]:
    """Success rate (%) per task id."""
    return {int(task): rate for task, rate in task_rates(parse_eval_info(path)).items()}
