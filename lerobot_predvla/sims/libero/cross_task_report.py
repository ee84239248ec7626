"""The report of `predvla blind-replay --cross-task`: plan task x evaluated task, beside each task's own plan.

From the per-evaluated-task files under OUT (`blind_replay_cross`), report.json (suite -> the matrix and per evaluated
task its own plan's and the other plans' successes), report.md and cross_task.png (a heatmap). The diagonal, each
task's own plan on its own task, is read from the own-task blind replay (`predvla blind-replay`, its OWN folder) on the
same states: the same episodes, since a replay depends only on the plan, the state and the seed.
"""

from pathlib import Path

import numpy as np

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.blind_replay import load_task, markdown_head, task_path
from lerobot_predvla.sims.libero.blind_replay_cross import TASKS_DIR
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text
from lerobot_predvla.utils.statistics import episode_totals, percent

REPORT_JSON, REPORT_MD, FIGURE = "report.json", "report.md", "cross_task.png"
TARGET_RATIO = 0.25  # a task's success with another task's instruction at most a quarter of its own


def _counts(successes: int, episodes: int) -> dict:
    return {"successes": successes, "episodes": episodes}


def own_plan(own_out: Path, suite: str, task_id: int, settings: dict) -> tuple[dict | None, dict | None]:
    """The task's own state-0 plan from the own-task blind replay under `own_out`: (its successes on the cross
    run's states, its successes on all its states), or (None, None) where that file is missing or was run under
    other settings (source state, cap, seed, settle steps, grasp rule) or on states not covering the cross run's."""
    own = load_task(task_path(own_out, suite, task_id))
    if own is None:
        return None, None
    same = {k: v for k, v in own["settings"].items() if k != "states"}
    if same != {k: v for k, v in settings.items() if k != "states"}:
        return None, None
    plan = own["plans"]["state0"]
    steps = plan["success_step"]
    if not all(str(s) in steps for s in settings["states"]):
        return None, None
    on_states = _counts(sum(steps[str(s)] is not None for s in settings["states"]), len(settings["states"]))
    return on_states, {**_counts(plan["successes"], plan["episodes"]), "states": plan["states"]}


def collect(out: Path, own_out: Path) -> dict:
    """report.json's content: suite -> {states, cap, tasks: evaluated task -> its numbers, totals}."""
    report = {}
    for suite in SUITES:
        files = sorted((Path(out) / TASKS_DIR / suite).glob("task*.json"), key=lambda p: int(p.stem[4:]))
        if not files:
            continue
        tasks = {}
        for path in files:
            task = load_task(path)
            if task is None:
                raise ValueError(f"{path}: unreadable per-task result; delete it to run that task again")
            same, own_all = own_plan(own_out, suite, task["task_id"], task["settings"])
            by_plan = {a: _counts(p["successes"], p["episodes"]) for a, p in task["plans"].items()}
            tasks[str(task["task_id"])] = {
                "task_name": task["task_name"], "language": task["language"], "by_plan": by_plan,
                "other_plans": _counts(*episode_totals(by_plan.values())),
                "own_plan_same_states": same, "own_plan": own_all}
        settings = load_task(files[0])["settings"]
        report[suite] = {
            "states": settings["states"], "cap": settings["cap"], "source_state": settings["source_state"],
            "tasks": tasks,
            "other_plans": _counts(*episode_totals(t["other_plans"] for t in tasks.values())),
            "own_plan_same_states": _total(t["own_plan_same_states"] for t in tasks.values()),
            "own_plan": _total(t["own_plan"] for t in tasks.values())}
    return report


def _total(rows) -> dict | None:
    rows = list(rows)
    return None if any(r is None for r in rows) else _counts(*episode_totals(rows))


def _pct(counts: dict | None) -> str:
    if not counts or not counts["episodes"]:
        return "—"
    return f"{counts['successes']}/{counts['episodes']} ({percent(counts['successes'], counts['episodes']):.1f}%)"


def _rate(counts: dict | None) -> float | None:
    return counts["successes"] / counts["episodes"] if counts and counts["episodes"] else None


def ratio_text(other: dict, own: dict | None) -> str:
    """Other plans' success rate over the own plan's, or why there is none."""
    r_other, r_own = _rate(other), _rate(own)
    if r_other is None or r_own is None:
        return "—"
    if r_own == 0:
        return "own 0" if r_other == 0 else "∞"
    return f"{r_other / r_own:.2f}"


def _states_text(states: list[int]) -> str:
    if len(states) > 1 and states == list(range(states[0], states[-1] + 1)):
        return f"{states[0]}-{states[-1]}"
    return ", ".join(map(str, states))


def markdown(report: dict, command: str) -> str:
    lines = markdown_head("What ignoring the instruction gets: blind plans across tasks of one scene",
             "Each *plan task*'s scripted-expert plan (its actions from an official init state, `--source-state`, "
             "0 by default) replayed action by action, with no observation, on the official init states of every "
             "other task of the same scene (the *evaluated task*), success judged by the evaluated task's goal. "
             "*Own plan*: the evaluated task's own state-0 plan on the same states, from the own-task blind replay"
             " (the same episodes). The other plans' rate is what another task's motion, done well and blind, gets"
             " by the evaluated task's goal: what a policy that follows a wrong instruction can expect by chance, "
             "while a policy that ignores the instruction scores the same whichever it is given.", command)
    for suite, r in report.items():
        tasks = r["tasks"]
        lines += [f"## {suite}", "",
                  f"Replay states {_states_text(r['states'])}, {r['cap']}-step cap. Other tasks' plans: "
                  f"**{_pct(r['other_plans'])}**; each task's own plan on the same states: "
                  f"**{_pct(r['own_plan_same_states'])}**, on the own-task run's states {_pct(r['own_plan'])}. Ratio "
                  f"other / own: {ratio_text(r['other_plans'], r['own_plan_same_states'])} on the same states, "
                  f"{ratio_text(r['other_plans'], r['own_plan'])} against the own-task run (the target for a "
                  f"policy, with another task's instruction against its own: at most {TARGET_RATIO} per task).", "",
                  "| evaluated task | own plan, same states | own plan, own-task states | other plans | other / own "
                  "(same states) | other / own (own-task states) | plans that succeed (successes) | name |",
                  "|---|---|---|---|---|---|---|---|"]
        for b, t in tasks.items():
            winners = ", ".join(f"{a} ({c['successes']})" for a, c in t["by_plan"].items() if c["successes"]) or "none"
            lines.append(f"| {b} | {_pct(t['own_plan_same_states'])} | {_pct(t['own_plan'])} | "
                         f"{_pct(t['other_plans'])} | {ratio_text(t['other_plans'], t['own_plan_same_states'])} | "
                         f"{ratio_text(t['other_plans'], t['own_plan'])} | {winners} | {t['task_name']} |")
        evaluated = list(tasks)
        plan_tasks = sorted({a for t in tasks.values() for a in t["by_plan"]} | set(evaluated), key=int)
        lines += ["", "Successes per plan task (row) and evaluated task (column); the diagonal (italic) is the own "
                  "plan on the same states:", "",
                  "| plan \\ evaluated | " + " | ".join(evaluated) + " |", "|---" * (len(evaluated) + 1) + "|"]
        for a in plan_tasks:
            cells = []
            for b in evaluated:
                if a == b:
                    own = tasks[b]["own_plan_same_states"]
                    cells.append(f"*{own['successes']}/{own['episodes']}*" if own else "—")
                else:
                    c = tasks[b]["by_plan"].get(a)
                    cells.append(f"{c['successes']}/{c['episodes']}" if c else "—")
            lines.append(f"| {a} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [f"![plan task x evaluated task]({FIGURE})", ""]
    return "\n".join(lines)


def matrix(r: dict) -> tuple[list[str], list[str], np.ndarray]:
    """(plan tasks, evaluated tasks, success % with NaN where not run), the diagonal from the own plan."""
    tasks = r["tasks"]
    evaluated = list(tasks)
    plan_tasks = sorted({a for t in tasks.values() for a in t["by_plan"]} | set(evaluated), key=int)
    grid = np.full((len(plan_tasks), len(evaluated)), np.nan)
    for i, a in enumerate(plan_tasks):
        for j, b in enumerate(evaluated):
            c = tasks[b]["own_plan_same_states"] if a == b else tasks[b]["by_plan"].get(a)
            if c and c["episodes"]:
                grid[i, j] = percent(c["successes"], c["episodes"])
    return plan_tasks, evaluated, grid


def figure(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(report), figsize=(6.4 * len(report), 5.6), squeeze=False)
    for ax, (suite, r) in zip(axes[0], report.items(), strict=True):
        plan_tasks, evaluated, grid = matrix(r)
        image = ax.imshow(grid, vmin=0, vmax=100, cmap="viridis")
        for i in range(len(plan_tasks)):
            for j in range(len(evaluated)):
                if not np.isnan(grid[i, j]):
                    ax.text(j, i, f"{grid[i, j]:.0f}", ha="center", va="center", fontsize=7,
                            color="black" if grid[i, j] > 60 else "white",
                            fontweight="bold" if plan_tasks[i] == evaluated[j] else "normal")
        ax.set_xticks(range(len(evaluated)), evaluated)
        ax.set_yticks(range(len(plan_tasks)), plan_tasks)
        ax.set_xlabel("evaluated task (its goal)")
        ax.set_ylabel("plan task (its state-0 plan)")
        ax.set_title(f"{suite}, states {_states_text(r['states'])}: other plans {_pct(r['other_plans'])},\n"
                     f"own plan (diagonal) {_pct(r['own_plan_same_states'])}", fontsize=9)
        fig.colorbar(image, ax=ax, label="success (%)", shrink=0.8)
    fig.suptitle("Blind plans across the tasks of one scene: success by the evaluated task's goal", fontsize=10)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)


def write_cross_report(out: Path, command: str, own_out: Path) -> dict:
    """report.json, report.md and the heatmap from every per-evaluated-task file under `out`."""
    report = collect(out, own_out)
    if not report:
        return report
    atomic_write_json(Path(out) / REPORT_JSON, report)
    atomic_write_text(Path(out) / REPORT_MD, markdown(report, command))
    figure(report, Path(out) / FIGURE)
    return report
