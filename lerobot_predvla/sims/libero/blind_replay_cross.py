"""What ignoring the instruction gets: one task's blind plan replayed on the other tasks of the same scene.

On a suite whose tasks start from one scene (libero_goal: the same fixtures, objects and initial regions; only the
instruction and the goal differ), a policy that ignores the instruction can still succeed on a task by doing another
task's motion when that motion happens to reach this task's goal too. This measures that rate with no policy at all:
the scripted expert's plan recorded on a *plan task* A from its official init state `source_state` (as
`blind_replay.record_plan` does), replayed action by action with no observation (`blind_replay.replay`: the settle
steps, the plan, idle up to the cap) on the official init states of an *evaluated task* B, success judged by B's goal
(`check_success()` of B's environment).

Two tasks share a scene when their BDDL files are equal once the instruction, the objects of interest and the goal
are removed, and their official init states have the same length (one simulator state vector): then A's plan is
a motion in B's world. Evaluated tasks of another scene are refused.

Files under OUT (resumable at the granularity of one plan on one evaluated task):
- plans/SUITE/taskA.json: A's plan (actions at full precision), the expert's outcome from its source state;
- tasks/SUITE/taskB.json: evaluated task B, per plan task A the step of success on each state (or null), rewritten
  after every plan finished on B.
"""

import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_predvla.sims.libero.blind_replay import Settings, load_task, record_plan, replay
from lerobot_predvla.sims.libero.env import make_env, official_init_states, task_spec
from lerobot_predvla.utils.io import atomic_write_json

DEFAULT_CROSS_OUT = Path("results/blind_replay_cross")
PLANS_DIR, TASKS_DIR = "plans", "tasks"
_NOT_SCENE = (re.compile(r"\(:language[^\n]*\n"), re.compile(r"\(:obj_of_interest.*?\)", re.S))


def plan_path(out: Path, suite: str, task_id: int) -> Path:
    return Path(out) / PLANS_DIR / suite / f"task{task_id}.json"


def evaluated_path(out: Path, suite: str, task_id: int) -> Path:
    return Path(out) / TASKS_DIR / suite / f"task{task_id}.json"


def scene_text(bddl: str) -> str:
    """A BDDL problem without what makes it a task: the instruction, the objects of interest and the goal."""
    for pattern in _NOT_SCENE:
        bddl = pattern.sub("", bddl)
    goal = bddl.find("(:goal")
    return bddl if goal < 0 else bddl[:goal]


def scene_groups(suite: str, task_ids: list[int]) -> list[list[int]]:
    """`task_ids` grouped by scene (equal `scene_text` and equal init-state length), in first-seen order."""
    groups: dict[tuple[str, int], list[int]] = {}
    for task_id in task_ids:
        key = (scene_text(task_spec(suite, task_id).bddl_file.read_text()),
               official_init_states(suite, task_id).shape[1])
        groups.setdefault(key, []).append(task_id)
    return list(groups.values())


@dataclass(frozen=True)
class Pair:
    """One plan task's plan replayed on one evaluated task's states."""

    suite: str
    plan_task: int
    evaluated_task: int


def pairs_to_run(out: Path, suite: str, plan_tasks: list[int], evaluated_tasks: list[int], settings: Settings,
                 strict: bool) -> list[Pair]:
    """Every (plan task, evaluated task other than itself, of the same scene) pair not already under `out` with these
    settings. A pair across scenes raises ValueError if `strict` (the evaluated tasks were named), else is left out;
    so does a file under `out` that holds other settings."""
    groups = scene_groups(suite, sorted({*plan_tasks, *evaluated_tasks}))
    scene_of = {t: i for i, group in enumerate(groups) for t in group}
    apart = [(a, b) for a in plan_tasks for b in evaluated_tasks if scene_of[a] != scene_of[b]]
    if apart and strict:
        raise ValueError(f"{suite}: (plan task, evaluated task) {apart[:5]} are of different scenes; the scenes "
                         f"group the tasks as {groups}")
    for a in plan_tasks:
        _check_settings(load_task(plan_path(out, suite, a)), plan_path(out, suite, a), settings)
    pairs = []
    for b in evaluated_tasks:
        done = load_task(evaluated_path(out, suite, b))
        _check_settings(done, evaluated_path(out, suite, b), settings)
        finished = set(done["plans"]) if done else set()
        pairs += [Pair(suite, a, b) for a in plan_tasks
                  if a != b and scene_of[a] == scene_of[b] and str(a) not in finished]
    return pairs


def _check_settings(done: dict | None, path: Path, settings: Settings) -> None:
    if done is not None and done.get("settings") != settings.as_dict():
        raise ValueError(f"{path} was run with other settings ({done.get('settings')}); pass another --out or "
                         "delete it to run it again")


def plan_for(out: Path, suite: str, task_id: int, settings: Settings) -> np.ndarray:
    """The plan task's actions: from its file under `out`, else recorded by the expert and written there."""
    path = plan_path(out, suite, task_id)
    done = load_task(path)
    if done is None:
        spec = task_spec(suite, task_id)
        env = make_env(spec)
        try:
            source = settings.source_state
            plan = record_plan(env, official_init_states(suite, task_id)[source], settings.seed + source, settings)
        finally:
            env.close()
        done = {"suite": suite, "task_id": task_id, "task_name": spec.name, "language": spec.language,
                "settings": settings.as_dict(), "source_state": source, "source_success": plan["success"],
                "source_steps": plan["steps"], "source_note": plan["note"], "plan": plan["actions"].tolist()}
        atomic_write_json(path, done)
    return np.asarray(done["plan"], dtype=np.float64)


def run_evaluated_task(out: Path, suite: str, task_id: int, plans: dict[int, np.ndarray], settings: Settings,
                       progress=None) -> dict:
    """Each of `plans` (plan task -> actions) replayed on evaluated task `task_id`'s `settings.states`, its file
    under `out` rewritten after every plan (so an interrupted run keeps the plans already finished)."""
    path = evaluated_path(out, suite, task_id)
    spec = task_spec(suite, task_id)
    init_states = official_init_states(suite, task_id)
    if max(settings.states) >= len(init_states):
        raise ValueError(f"{suite} task {task_id} has {len(init_states)} official init states; --states asks for "
                         f"{max(settings.states)}")
    result = load_task(path) or {"suite": suite, "task_id": task_id, "task_name": spec.name,
                                 "language": spec.language, "settings": settings.as_dict(), "plans": {}}
    env = make_env(spec)
    try:
        for plan_task, actions in plans.items():
            t0 = time.time()
            outcomes = {}
            for state in settings.states:
                outcomes[str(state)] = replay(env, init_states[state], actions, settings.seed + state, settings)
                if progress is not None:
                    progress()
            result["plans"][str(plan_task)] = {
                "plan_task_name": task_spec(suite, plan_task).name, "states": list(settings.states),
                "success_step": outcomes, "successes": sum(v is not None for v in outcomes.values()),
                "episodes": len(outcomes), "seconds": round(time.time() - t0, 1)}
            result["plans"] = dict(sorted(result["plans"].items(), key=lambda kv: int(kv[0])))
            atomic_write_json(path, result)
    finally:
        env.close()
    return result
