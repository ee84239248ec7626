"""Scripted against teleop demonstrations (and teleop from shifted placements), measured on a sample: success,
lengths, no-op steps, end-effector path spread at matched phase, placement spread, and one teleop plan replayed blind.
Physics only; writes OUT/report.json, report.md and styles.png (docs/research/demonstrations.md).

  python -m research.demo_styles --tasks 0,1,2 --per-task 10 --out results/demonstrations
"""

import argparse
import json
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_predvla.cli.arguments import int_list
from lerobot_predvla.sims.libero.blind_replay import Settings, plan_replays, task_path
from lerobot_predvla.sims.libero.env import OFFICIAL_INIT_NOISE, make_env, official_init_states, task_spec
from lerobot_predvla.sims.libero.expert.teleop import TELEOP, TeleopParams
from lerobot_predvla.sims.libero.geometry import GRIP_SITE
from lerobot_predvla.sims.libero.placement import object_positions
from lerobot_predvla.sims.libero.protocol import STEP_CAPS
from lerobot_predvla.sims.libero.record import episode_seed
from lerobot_predvla.sims.libero.rollout import Episode, run_episode
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text

PHASES = (0.25, 0.5, 0.75)  # normalised times at which the paths are compared
NOOP_THRESHOLD = 1e-4  # OpenVLA's LIBERO no-op filter: |motion command| below this and the gripper unchanged


@dataclass(frozen=True)
class Variant:
    """One way of making demonstrations: who executes the plan, and how far the placements are shifted (m)."""

    name: str
    teleop: TeleopParams | None
    placement_spread: float = 0.0


VARIANTS = (Variant("scripted", None), Variant("teleop", TELEOP), Variant("teleop_placed", TELEOP, 0.03))


def noop_mask(actions: np.ndarray) -> np.ndarray:
    """Which steps OpenVLA's LIBERO filter drops: the motion command's norm below NOOP_THRESHOLD and the gripper
    command equal to the previous step's (the first step: the motion command alone)."""
    still = np.linalg.norm(actions[:, :6], axis=1) < NOOP_THRESHOLD
    same_grip = np.r_[True, actions[1:, 6] == actions[:-1, 6]]
    return still & same_grip


def eef_path(env, states: np.ndarray) -> np.ndarray:
    """End-effector (grip site) positions of the saved simulator states, shape (N, 3)."""
    sim = env.sim
    site = sim.model.site_name2id(GRIP_SITE)
    path = []
    for state in states:
        sim.set_state_from_flattened(state)
        sim.forward()
        path.append(sim.data.site_xpos[site].copy())
    return np.array(path)


def at_phase(path: np.ndarray, phase: float) -> np.ndarray:
    """The path's point at normalised time `phase` (nearest step)."""
    return path[int(round(phase * (len(path) - 1)))]


def phase_spread(paths: list[np.ndarray]) -> dict[str, float]:
    """Per phase in PHASES: the root of the summed per-axis variances (m) of the paths' points at that phase."""
    return {str(p): float(np.sqrt(np.var([at_phase(q, p) for q in paths], axis=0).sum())) for p in PHASES}


def _episode_row(env, episode: Episode) -> dict:
    if not episode.success:
        return {"success": False, "note": episode.note}
    path = eef_path(env, episode.states)
    env.sim.set_state_from_flattened(episode.states[0])
    env.sim.forward()
    return {"success": True, "steps": len(episode.actions), "noop": int(noop_mask(episode.actions).sum()),
            "path": path, "placements": object_positions(env)[:, :2]}


def sample_task(task_id: int, n: int, seed: int, suite: str = "libero_object", half_turn: str = "wrist_centre",
                progress=None) -> dict:
    """Every variant's `n` attempts on one task, as `predvla demos` would roll them out with the Table 2 dataset's
    settings (arm start noise OFFICIAL_INIT_NOISE, `half_turn`)."""
    spec = task_spec(suite, task_id)
    env = make_env(spec, init_noise=OFFICIAL_INIT_NOISE)
    out = {}
    try:
        for variant in VARIANTS:
            rows = []
            for attempt in range(n):
                episode = run_episode(env, episode_seed(seed, task_id, attempt), STEP_CAPS[suite], half_turn,
                                      teleop=variant.teleop, placement_spread=variant.placement_spread)
                rows.append(_episode_row(env, episode))
                if progress:
                    progress()
            out[variant.name] = rows
    finally:
        env.close()
    return {"name": spec.name, "variants": out}


def summarise(rows: list[dict]) -> dict:
    """A variant's numbers on one task from its episode rows."""
    ok = [r for r in rows if r["success"]]
    steps = [r["steps"] for r in ok]
    placements = np.array([r["placements"] for r in ok]) if ok else np.zeros((0, 0, 2))
    return {"attempts": len(rows), "successes": len(ok), "steps": steps,
            "noop_fraction": sum(r["noop"] for r in ok) / max(sum(steps), 1),
            "path_spread_m": phase_spread([r["path"] for r in ok]) if len(ok) > 1 else None,
            "placement_std_m": float(placements.std(axis=0).mean()) if len(ok) > 1 else None,
            "failures": sorted({r["note"] for r in rows if not r["success"]})}


def blind_teleop_plan(task_id: int, states: tuple[int, ...], suite: str = "libero_object") -> dict:
    """The teleop plan from official init state 0 (the teleoperator model at diversity 1, seeded by the episode's seed,
    0) replayed blind on its own state and on `states`: `predvla blind-replay --style teleop`'s state-0 plan
    (`blind_replay.plan_replays`)."""
    settings = Settings(states=states, style="teleop")
    env = make_env(task_spec(suite, task_id))
    try:
        plan = plan_replays(env, official_init_states(suite, task_id), 0, settings)
    finally:
        env.close()
    return {"task_id": task_id, "settings": settings.as_dict(), "source_success": plan["source_success"],
            "plan_steps": plan["source_steps"], "own_replay_step": plan["source_replay_step"],
            "success_step": plan["success_step"], "successes": plan["successes"], "episodes": plan["episodes"]}


def scripted_blind_plan(committed: Path, states: tuple[int, ...]) -> dict:
    """The scripted plan from official init state 0 on `states`, read from `predvla blind-replay`'s committed per-task
    file (`committed`, e.g. results/blind_replay/tasks/libero_object/task0.json)."""
    plan = json.loads(Path(committed).read_text())["plans"]["state0"]
    missing = [s for s in states if str(s) not in plan["success_step"]]
    if missing:
        raise ValueError(f"{committed}: the state-0 plan was not replayed on states {missing}")
    outcomes = {str(s): plan["success_step"][str(s)] for s in states}
    return {"source": str(committed), "plan_steps": plan["source_steps"], "success_step": outcomes,
            "successes": sum(v is not None for v in outcomes.values()), "episodes": len(outcomes)}


def run(tasks: list[int], n: int, seed: int, blind_states: tuple[int, ...], scripted_blind: Path, out: Path,
        command: str, progress=None) -> dict:
    """The whole comparison; writes report.json, report.md and styles.png under `out`."""
    t0 = time.time()
    samples = {str(t): sample_task(t, n, seed, progress=progress) for t in tasks}
    report = {"command": command, "tasks": {}, "blind": {}}
    for task, sample in samples.items():
        report["tasks"][task] = {"name": sample["name"],
                                 **{v: summarise(rows) for v, rows in sample["variants"].items()}}
    report["blind"]["teleop"] = blind_teleop_plan(tasks[0], blind_states)
    report["blind"]["scripted"] = scripted_blind_plan(scripted_blind, blind_states)
    report["seconds"] = round(time.time() - t0)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "report.json", report)
    atomic_write_text(out / "report.md", markdown(report))
    figure(samples[str(tasks[0])], out / "styles.png")
    return report


def _pooled(report: dict, variant: str) -> dict:
    rows = [t[variant] for t in report["tasks"].values()]
    steps = [s for r in rows for s in r["steps"]]
    spreads = [r["path_spread_m"] for r in rows if r["path_spread_m"]]
    return {"successes": sum(r["successes"] for r in rows), "attempts": sum(r["attempts"] for r in rows),
            "steps": steps, "noop": sum(r["noop_fraction"] * sum(r["steps"]) for r in rows) / max(sum(steps), 1),
            "spread": {p: float(np.mean([s[str(p)] for s in spreads])) for p in PHASES},
            "placement": float(np.mean([r["placement_std_m"] for r in rows if r["placement_std_m"] is not None]))}


def markdown(report: dict) -> str:
    lines = ["# Scripted and teleop demonstrations, measured", "", "Reproduce:", "", "```bash", report["command"],
             "```", "", f"Tasks {', '.join(report['tasks'])} of libero_object; {report['seconds']} s.", "",
             "| variant | success | steps: mean (min-max) | no-op steps | eef spread at t=0.25 / 0.5 / 0.75 (cm) "
             "| object placement std (mm) |", "|---|---|---|---|---|---|"]
    for variant in (v.name for v in VARIANTS):
        p = _pooled(report, variant)
        steps = p["steps"] or [0]
        spread = " / ".join(f"{100 * p['spread'][q]:.1f}" for q in PHASES)
        lines.append(f"| {variant} | {p['successes']}/{p['attempts']} | {np.mean(steps):.0f} ({min(steps)}-"
                     f"{max(steps)}) | {100 * p['noop']:.1f}% | {spread} | {1000 * p['placement']:.1f} |")
    lines += ["", "Per task:", "",
              "| task | variant | success | steps | no-op | eef spread (cm) | placement std (mm) |",
              "|---|---|---|---|---|---|---|"]
    for task, row in report["tasks"].items():
        for variant in (v.name for v in VARIANTS):
            r = row[variant]
            spread = " / ".join(f"{100 * r['path_spread_m'][str(q)]:.1f}" for q in PHASES) if r["path_spread_m"] \
                else "—"
            placement = f"{1000 * r['placement_std_m']:.1f}" if r["placement_std_m"] is not None else "—"
            lines.append(f"| {task} | {variant} | {r['successes']}/{r['attempts']} | {np.mean(r['steps'] or [0]):.0f} |"
                         f" {100 * r['noop_fraction']:.1f}% | {spread} | {placement} |")
    b, s = report["blind"]["teleop"], report["blind"]["scripted"]
    lines += ["", f"Blind replay, task {b['task_id']}, plan from official init state 0 replayed on states "
              f"{min(map(int, b['success_step']))}-{max(map(int, b['success_step']))}: teleop plan "
              f"({b['plan_steps']} steps, own start {'yes' if b['own_replay_step'] else 'no'}) "
              f"{b['successes']}/{b['episodes']}; scripted plan ({s['plan_steps']} steps) {s['successes']}/"
              f"{s['episodes']}.", "", "![paths](styles.png)", ""]
    return "\n".join(lines)


def figure(sample: dict, path: Path, shown: int = 5) -> None:
    """Top view (x, y) of the end effector's path in the first `shown` successful demonstrations of each variant of
    one task, and their heights over normalised time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = list(sample["variants"])
    fig, axes = plt.subplots(2, len(variants), figsize=(4.2 * len(variants), 7.5), squeeze=False)
    for col, variant in enumerate(variants):
        ok = [r for r in sample["variants"][variant] if r["success"]][:shown]
        for k, row in enumerate(ok):
            eef, color = row["path"], f"C{k}"
            axes[0, col].plot(eef[:, 0], eef[:, 1], color=color, lw=1)
            axes[0, col].plot(*eef[0, :2], "o", color=color, ms=3)
            axes[1, col].plot(np.linspace(0, 1, len(eef)), eef[:, 2], color=color, lw=1)
        axes[0, col].set_title(f"{variant}: {len(ok)} demonstrations (top view)", fontsize=9)
        axes[0, col].set_xlabel("x (m)")
        axes[0, col].set_ylabel("y (m)")
        axes[0, col].set_aspect("equal", adjustable="datalim")
        axes[1, col].set_xlabel("normalised time")
        axes[1, col].set_ylabel("end-effector height (m)")
    fig.suptitle(f"{sample['name']}: end-effector paths by demonstration style", fontsize=10)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)





DEFAULT_OUT = Path("results/demonstrations")
COMMITTED_BLIND = Path("results/blind_replay")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m research.demo_styles", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", type=int_list("--tasks"), default=[0, 1, 2],
                   help="libero_object task ids (default 0-2); the first one's plan is replayed blind")
    p.add_argument("--per-task", type=int, default=10, help="attempts per task and variant (default 10)")
    p.add_argument("--seed", type=int, default=0, help="demonstration seed, as `predvla demos --seed` (default 0)")
    p.add_argument("--blind-states", type=int_list("--blind-states"), default=list(range(1, 20)),
                   help="official init states the teleop plan from state 0 is replayed on (default 1-19)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.per_task < 2:
        raise SystemExit(f"--per-task must be >= 2 (a spread needs two demonstrations), got {args.per_task}")
    committed = task_path(COMMITTED_BLIND, "libero_object", args.tasks[0])
    if not committed.is_file():
        raise SystemExit(f"{committed} is missing: the scripted plan's blind replay of task {args.tasks[0]} "
                         "(`predvla blind-replay --suites libero_object`) is the comparison")
    command = shlex.join(["python", "-m", "research.demo_styles", *(sys.argv[1:] if argv is None else argv)])
    with tqdm(total=len(args.tasks) * len(VARIANTS) * args.per_task, desc="episodes", unit="episode") as bar:
        report = run(args.tasks, args.per_task, args.seed, tuple(args.blind_states), committed, args.out, command,
                     progress=lambda: bar.update(1))
    print((args.out / "report.md").read_text())
    print(f"wrote {args.out}/report.json, report.md, styles.png ({report['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
