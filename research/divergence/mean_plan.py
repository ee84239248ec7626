"""`python -m research.divergence.mean_plan`: is the time-aligned mean of a task's demonstrations itself a plan?

A policy that never reads an observation and reproduces the average of its demonstrations step by step commands their
time-aligned mean (`simulation.mean_demo`). Where the demonstrations agree in timing (the scripted expert) that mean
is close to each of them; where their timing varies (the teleoperator model's idle stretches, speeds and overshoots)
it blends phases: at one step some demonstrations still descend while others have closed the gripper and lift.

Per task, this replays without observation, from the same official init states and as `predvla blind-replay` starts
them (`blind_replay.start`: the state, the settle steps, the fixture poses of its seed), two plans: `mean`, the
time-aligned mean of every demonstration of the task's file, and `demo`, one demonstration's own actions (a blind
replay, for reference). Per start it records whether the episode succeeds and where the hand is, relative to the
object to pick (`simulation.target_object`), at the step the plan first commands the gripper closed. Physics only.

  python -m research.divergence.mean_plan --hdf5-root outputs/libero_object_teleop_placed/hdf5 --tasks 2,3,6 \\
      --states 0-9 --out results/demonstrations/teleop_placed/mean_plan

Writes OUT/mean_plan.json, mean_plan.md and mean_plan.png.
"""

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

from lerobot_predvla.cli.demos import task_ids
from lerobot_predvla.sims.libero.blind_replay import Settings, start
from lerobot_predvla.sims.libero.env import make_env, official_init_states, task_spec
from lerobot_predvla.sims.libero.object_shift import pose
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH
from lerobot_predvla.sims.libero.rollout import IDLE
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text
from research.divergence.simulation import demo_file, mean_demo, read_all_actions, target_object
from research.er_correction import close_step
from research.er_timing import state_range

PLANS = ("mean", "demo")
REPORT_JSON, REPORT_MD, FIGURE = "mean_plan.json", "mean_plan.md", "mean_plan.png"
COMMAND = "python -m research.divergence.mean_plan"


def task_plans(actions: list[np.ndarray], demo: int) -> dict[str, np.ndarray]:
    """The two plans of a task: the time-aligned mean of `actions` and demonstration `demo`'s own actions."""
    if not 0 <= demo < len(actions):
        raise ValueError(f"--demo {demo}: the file has demonstrations 0-{len(actions) - 1}.")
    return {"mean": mean_demo(actions), "demo": np.asarray(actions[demo])}


def hand_position(env) -> np.ndarray:
    """The end effector's position (robosuite's `robot0_eef_pos`)."""
    return env.sim.data.site_xpos[env.env.robots[0].eef_site_id].copy()


def play(env, plan: np.ndarray, cap: int) -> dict:
    """`plan` then idle steps up to `cap` from where `env` stands, without observation: the step of the first
    success (None: none), the plan's first close step and the hand minus the object to pick there (m; None when the
    plan never closes the gripper)."""
    close = close_step(plan)
    name = target_object(env)
    offset, success = None, None
    for t in range(cap):
        if t == close:
            offset = (hand_position(env) - pose(env, name)[:3]).tolist()
        env.step(plan[t] if t < len(plan) else IDLE)
        if env.check_success():
            success = t + 1
            break
    return {"close": close, "offset_m": offset, "success_step": success}


def run_task(hdf5_root: Path, suite: str, task_id: int, states: list[int], demo: int, cap: int) -> dict:
    """Both plans of one task replayed from each of `states` (official init states, blind replay's start)."""
    spec = task_spec(suite, task_id)
    path = demo_file(hdf5_root, suite, spec.name)
    if not path.is_file():
        raise ValueError(f"--hdf5-root {hdf5_root}: no demonstrations of task {task_id} ({path} missing).")
    actions = read_all_actions(path)
    plans = task_plans(actions, demo)
    init_states = official_init_states(suite, task_id)
    if max(states) >= len(init_states):
        raise ValueError(f"--states: task {task_id} has official init states 0-{len(init_states) - 1}.")
    settings = Settings(states=tuple(states), cap=cap)
    env = make_env(spec)
    episodes = {name: [] for name in PLANS}
    try:
        for state in states:
            for name, plan in plans.items():
                start(env, init_states, state, settings)
                episodes[name].append({"state": state, **play(env, plan, cap)})
    finally:
        env.close()
    lengths = [len(a) for a in actions]
    return {"task": task_id, "file": path.name, "demonstrations": len(actions),
            "demo_close_steps": [close_step(a) for a in actions], "demo_lengths": [min(lengths), max(lengths)],
            "plan_lengths": {name: len(plan) for name, plan in plans.items()}, "episodes": episodes}


def summary(episodes: list[dict]) -> dict:
    """Successes, and the median hand-minus-object offset at the plan's close (cm) over the starts."""
    offsets = np.array([e["offset_m"] for e in episodes if e["offset_m"] is not None])
    return {"successes": sum(e["success_step"] is not None for e in episodes), "episodes": len(episodes),
            "close": episodes[0]["close"],
            "median_offset_cm": (100 * np.median(offsets, axis=0)).round(1).tolist() if len(offsets) else None}


def markdown(report: dict) -> str:
    lines = ["# Is the mean of the demonstrations a plan?", "",
             f"Demonstrations: `{report['hdf5_root']}`; official init states {report['states_text']}, "
             f"{report['cap']}-step cap, no observation. `mean`: the time-aligned mean of every demonstration of the "
             f"task; `demo`: demonstration {report['demo']}'s own actions. Offset: the hand minus the object to pick "
             "(cm, median over the starts) at the step the plan first commands the gripper closed.", "",
             "Reproduce:", "", "```bash", report["command"], "```", "",
             "| task | demonstrations: first close step (min-median-max) | plan | closes at | successes | "
             "offset x, y, z (cm) |", "|---|---|---|---|---|---|"]
    for task in report["tasks"].values():
        closes = [c for c in task["demo_close_steps"] if c is not None]
        span = f"{min(closes)}-{int(np.median(closes))}-{max(closes)}" if closes else "never"
        for name in PLANS:
            s = task["summary"][name]
            offset = ", ".join(f"{v:+.1f}" for v in s["median_offset_cm"]) if s["median_offset_cm"] else "-"
            lines.append(f"| {task['task']} | {span} ({task['demonstrations']}) | {name} | "
                         f"{s['close'] if s['close'] is not None else 'never'} | {s['successes']}/{s['episodes']} | "
                         f"{offset} |")
    return "\n".join(lines) + "\n"


def figure(report: dict, path: Path) -> None:
    """Per task, each start's hand-minus-object offset at the plan's close: horizontal distance against height,
    one colour per plan, filled where the episode succeeded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(report["tasks"].values())
    fig, axes = plt.subplots(1, len(tasks), figsize=(3.6 * len(tasks), 3.4), squeeze=False, sharey=True)
    for ax, task in zip(axes[0], tasks, strict=True):
        for name, colour in zip(PLANS, ("tab:red", "tab:blue"), strict=True):
            points = [(e["offset_m"], e["success_step"] is not None) for e in task["episodes"][name]
                      if e["offset_m"] is not None]
            for offset, succeeded in points:
                ax.scatter(100 * np.hypot(offset[0], offset[1]), 100 * offset[2], s=28, edgecolors=colour,
                           facecolors=colour if succeeded else "none")
            ax.scatter([], [], color=colour, label=f"{name} ({task['summary'][name]['successes']}/"
                                                   f"{task['summary'][name]['episodes']})")
        ax.set_title(f"task {task['task']}")
        ax.set_xlabel("horizontal distance to the object (cm)")
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("hand above the object (cm)")
    fig.suptitle("Hand at the plan's first close, per start (filled: the episode succeeded)", fontsize=10)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=90)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=COMMAND, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--hdf5-root", type=Path, required=True, help="demonstrations root (files in ROOT/SUITE/)")
    p.add_argument("--suite", default="libero_object")
    p.add_argument("--tasks", type=task_ids, required=True, help="task ids, e.g. 2,3,6")
    p.add_argument("--states", default="0-9", metavar="A-B", help="official init states to start from (default 0-9)")
    p.add_argument("--demo", type=int, default=0, help="the demonstration replayed as `demo` (default 0)")
    p.add_argument("--cap", type=int, default=PAPER_EPISODE_LENGTH, help="step cap (default: the paper's 600)")
    p.add_argument("--out", type=Path, required=True, help="directory for mean_plan.json/.md/.png")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
    try:
        states = state_range(args.states)
        tasks = {}
        for task_id in args.tasks:
            task = run_task(args.hdf5_root, args.suite, task_id, states, args.demo, args.cap)
            task["summary"] = {name: summary(task["episodes"][name]) for name in PLANS}
            tasks[str(task_id)] = task
            print(f"task {task_id}: " + ", ".join(f"{name} {s['successes']}/{s['episodes']}"
                                                   for name, s in task["summary"].items()), flush=True)
    except ValueError as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    report = {"hdf5_root": str(args.hdf5_root), "suite": args.suite, "states": states, "states_text": args.states,
              "demo": args.demo, "cap": args.cap, "command": f"{COMMAND} {shlex.join(argv)}", "tasks": tasks}
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / REPORT_JSON, report)
    atomic_write_text(args.out / REPORT_MD, markdown(report))
    figure(report, args.out / FIGURE)
    print((args.out / REPORT_MD).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
