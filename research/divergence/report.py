"""`python -m research.divergence`'s outputs: the measurement (simulation.py) run over the chosen tasks, written as
OUT/divergence.json, one figure per task (OUT/task<k>.png) and OUT/summary.md (the main numbers as markdown tables,
what the write-up quotes).
"""

import json
from pathlib import Path

import numpy as np

from lerobot_predvla.sims.libero.env import num_tasks, task_spec
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json
from research.divergence.simulation import (
    BLIND_IDLE_STEPS,
    EFFECT_WINDOWS,
    ENVELOPE_MARGIN,
    ENVELOPE_MIN_DEMOS,
    EXIT_RUN,
    LIFT_RISE_M,
    PHASES,
    SEPARATION_THRESHOLDS_M,
    TOP_MARGIN_M,
    OpenLoop,
    demo_file,
    gripper_width,
    instruction_effect,
    mean_demo,
    read_all_actions,
    run_task,
    window_means,
)

PHASE_COLOURS = {"approach": "0.95", "grasp": "#fde0c5", "lift": "#d9f0d3", "carry/place": "#dbe9f6",
                 "release": "#eadcf2"}
ROT_LS = (0, (6, 2, 1, 2))
ACTION_NAMES = ("dx", "dy", "dz", "droll", "dpitch", "dyaw", "gripper")


def shade(ax, bounds: dict[str, int], end: int, labels: bool = False) -> None:
    ends = [bounds[p] for p in PHASES[1:]] + [end]
    for phase, e in zip(PHASES, ends, strict=True):
        if e > bounds[phase]:
            ax.axvspan(bounds[phase], e, color=PHASE_COLOURS[phase], lw=0, zorder=0,
                       label=phase if labels else None)


def plot_task(path: Path, arrays: dict, numbers: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves, offline = arrays["curves"], arrays["offline"]
    first = curves[0]
    fig, axes = plt.subplots(4, 4, figsize=(19, 13))
    colours = [f"C{i}" for i in range(len(curves))]
    end = max(len(c["demo"].actions) for c in curves)
    xmax = max(end, *(len(c["rollouts"]["open_loop"]["ee_pos"]) for c in curves))
    for k, label in enumerate(("x", "y", "z")):
        ax = axes[0, k]
        shade(ax, first["bounds"], len(first["demo"].actions), labels=k == 0)
        for c, col in zip(curves, colours, strict=True):
            ax.plot(c["demo"].ee_pos[:, k], color=col, lw=1.5, label=f"demo {c['demo'].index}")
            ax.plot(c["rollouts"]["open_loop"]["ee_pos"][:, k], color=col, lw=1, ls="--",
                    label="open loop" if c is first else None)
            if "blind_plan" in c["rollouts"]:
                ax.plot(c["rollouts"]["blind_plan"]["ee_pos"][:, k], color=col, lw=0.8, ls=":",
                        label="another demo's plan, blind" if c is first else None)
            ax.plot(c["rollouts"]["open_loop_demo_rotation"]["ee_pos"][:, k], color=col, lw=0.7, ls=ROT_LS,
                    alpha=0.8, label="open loop, demo's rotation" if c is first else None)
        ax.set(title=f"end effector {label} (m); solid demo, dashed open loop", xlim=(0, xmax))
    axes[0, 0].legend(fontsize=7, loc="best")
    ax = axes[0, 3]
    shade(ax, first["bounds"], len(first["demo"].actions))
    for c, col in zip(curves, colours, strict=True):
        ax.plot(gripper_width(c["demo"].gripper), color=col, lw=1.5)
        ax.plot(gripper_width(c["rollouts"]["open_loop"]["gripper"]), color=col, lw=1, ls="--")
        ax.plot(c["rollouts"]["open_loop"]["object_pos"][:, 2] - c["rollouts"]["open_loop"]["object_pos"][0, 2],
                color=col, lw=0.8, ls="-.")
    ax.set(title="gripper width (m; solid demo, dashed open loop);\nopen loop's target object rise (m, dash-dot)",
           xlim=(0, xmax))
    panels = ((axes[1, 0], "ee_distance_m", "end-effector distance to the demo (m)"),
              (axes[1, 1], "joint_error_rad", "joint error to the demo (rad, L2 over 7 joints)"),
              (axes[1, 2], "orientation_error_rad", "end-effector orientation error to the demo (rad)"))
    for ax, key, title in panels:
        shade(ax, first["bounds"], len(first["demo"].actions))
        for c, col in zip(curves, colours, strict=True):
            ax.plot(c["cmp"]["open_loop"]["curves"][key], color=col, lw=1.2,
                    label="open loop" if c is first else None)
            if "blind_plan" in c["cmp"]:
                ax.plot(c["cmp"]["blind_plan"]["curves"][key], color=col, lw=0.8, ls=":",
                        label="another demo's plan, blind" if c is first else None)
            ax.plot(c["cmp"]["replay"]["curves"][key], color=col, lw=0.8, ls="-.",
                    label="own actions replayed" if c is first else None)
            ax.plot(c["cmp"]["open_loop_demo_rotation"]["curves"][key], color=col, lw=0.7, ls=ROT_LS, alpha=0.8,
                    label="open loop, demo's rotation" if c is first else None)
        if key == "ee_distance_m":
            for th in (0.02, 0.05):
                ax.axhline(th, color="0.5", lw=0.6, ls="--")
        ax.set(title=title + "\nphases of the first demo shaded", yscale="log", xlim=(0, end))
        ax.legend(fontsize=7)
    ax = axes[1, 3]
    med = arrays["median_bounds"]
    h = offline["horizon"]
    shade(ax, med, h)
    ax.plot(offline["mse_vs_demos"], "k", lw=1.2, label="open loop vs every demo (mean)")
    ax.plot(offline["mse_vs_mean"], "C3", lw=1, label="open loop vs mean demo")
    ax.plot(offline["demo_spread"], "0.5", lw=1, ls="--", label="demos vs mean demo (spread)")
    ax.plot(offline["instruction_effect_open_loop"], "C4", lw=1, ls=":",
            label="open loop vs other instructions' open loop")
    ax.plot(offline["instruction_effect_demos"], "C2", lw=1, ls=":", label="mean demo vs other tasks' mean demos")
    for c, col in zip(curves, colours, strict=True):
        ax.plot(c["action_err"], color=col, lw=0.6, alpha=0.7)
    ax.set(title=f"action MSE per step, raw units (all {numbers['demos_in_file']} demos; thin: vs each\n"
                 "simulated demo); phases from here on: median over the demos", yscale="log", xlim=(0, h))
    ax.legend(fontsize=7)
    ol = arrays["open_loop"]
    for ax, k in zip([*axes[2], *axes[3][:3]], range(7), strict=True):
        shade(ax, med, h)
        ax.fill_between(range(h), offline["low"][:, k], offline["high"][:, k], color="0.75", lw=0,
                        label="demos' min-max")
        ax.plot(offline["mean"][:, k], "k", lw=1, label="mean demo")
        ax.plot(ol[:h, k], "C3", lw=1.2, label="open loop")
        exit_step = numbers["offline"]["first_exit_step_per_dim"][str(k)]
        if exit_step >= 0:
            ax.axvline(exit_step, color="C3", lw=0.6, ls=":")
        ax.set(title=f"action {ACTION_NAMES[k]}: the demos' envelope (dotted: open loop leaves it)", xlim=(0, h))
        if k == 0:
            ax.legend(fontsize=7)
    axes[3, 3].axis("off")
    for ax in axes.flat:
        ax.set_xlabel("control step")
        ax.title.set_fontsize(8)
        ax.tick_params(labelsize=7)
    fig.suptitle(f"task {numbers['task_id']}: {numbers['instruction']}: exact open loop from each demo's own start",
                 fontsize=11)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=80)
    plt.close(fig)


def run(checkpoint: Path, hdf5_root: Path, tasks: list[int], demos: int, cap: int, out: Path,
        suite: str = "libero_object", log=print, merge: bool = False) -> dict:
    """Writes OUT/task<k>.png, OUT/divergence.json and OUT/summary.md. With `merge`, the tasks of an existing
    OUT/divergence.json of the same checkpoint, demonstrations and cap are kept (their figures stay as they are)
    and the tasks run now are added or replaced."""
    out.mkdir(parents=True, exist_ok=True)
    open_loop = OpenLoop(checkpoint)
    other_open_loops, other_mean_demos = {}, {}
    for k in range(num_tasks(suite)):
        spec = task_spec(suite, k)
        other_open_loops[k] = open_loop.actions(spec.language, cap)
        path = demo_file(hdf5_root, suite, spec.name)
        if path.is_file():
            other_mean_demos[k] = mean_demo(read_all_actions(path))
    # How much the instruction changes the actions at each step, for every task of the suite (offline): the open
    # loop against the open loop under each other instruction, the mean demonstration against the other tasks'.
    effect = {}
    for k, ol_k in other_open_loops.items():
        if k not in other_mean_demos:
            continue
        h = min(len(other_mean_demos[k]), cap)
        effect[str(k)] = {
            "open_loop_vs_other_instructions": window_means(instruction_effect(
                ol_k, [v for j, v in other_open_loops.items() if j != k], h)),
            "mean_demo_vs_other_tasks": window_means(instruction_effect(
                other_mean_demos[k], [v for j, v in other_mean_demos.items() if j != k], h)),
            "other_tasks_with_demos": sorted(j for j in other_mean_demos if j != k)}
    report = {"checkpoint": str(checkpoint), "hdf5_root": str(hdf5_root), "suite": suite, "cap": cap,
              "demos_per_task": demos, "separation_thresholds_m": list(SEPARATION_THRESHOLDS_M),
              "phase_rule": {"lift_rise_m": LIFT_RISE_M, "top_margin_m": TOP_MARGIN_M},
              "envelope": {"min_demo_fraction": ENVELOPE_MIN_DEMOS, "exit_run_steps": EXIT_RUN,
                           "margin": ENVELOPE_MARGIN},
              "blind_idle_steps": BLIND_IDLE_STEPS, "instruction_effect_windows": [list(w) for w in EFFECT_WINDOWS],
              "instruction_effect_by_task": effect, "tasks": {}}
    previous = out / "divergence.json"
    if merge and previous.is_file():
        old = load_report(previous)
        same = ("checkpoint", "hdf5_root", "suite", "cap")
        if any(old.get(k) != report[k] for k in same):
            raise ValueError(f"{previous}: another run ({', '.join(f'{k}={old.get(k)}' for k in same)}); cannot merge")
        report["tasks"] = {k: v for k, v in old["tasks"].items() if int(k) not in tasks}
        report["merged_from_earlier_runs"] = sorted(report["tasks"], key=int)
    for task_id in tasks:
        numbers, arrays = run_task(open_loop, hdf5_root, task_id, demos, cap, suite, log, other_open_loops,
                                   other_mean_demos)
        report["tasks"][str(task_id)] = numbers
        atomic_write_json(out / "divergence.json", report)  # before the figure: the numbers are the costly part
        plot_task(out / f"task{task_id}.png", arrays, numbers)
    report["tasks"] = dict(sorted(report["tasks"].items(), key=lambda kv: int(kv[0])))
    atomic_write_json(out / "divergence.json", report)
    (out / "summary.md").write_text(markdown_summary(report))
    return report


def load_report(path: Path) -> dict:
    return json.loads(Path(path).read_text())


def _cm(value: float) -> str:
    return f"{value * 100:.1f}"


def _sep(row: dict, name: str, key: str) -> str:
    sep = row[name]["separation"][key]
    return "never" if sep["step"] < 0 else f"{sep['step']} ({sep['phase']})"


def markdown_summary(report: dict) -> str:
    """The report's main numbers as markdown tables (what the write-up quotes)."""
    lines = ["| task | demo | length | phases (grasp, lift, carry, release) | open loop leaves by 2 cm | by 5 cm | "
             "at the demo's close: distance (cm), height above (cm), yaw error (rad) | open loop success | "
             "with the demo's rotation | another demo's plan, blind | own replay max (cm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        for row in task["demos"]:
            ph = row["phases"]
            close = row["open_loop"]["at_demo_close"]
            blind = row.get("blind_plan")

            def success(r):
                return "no" if r["success_step"] < 0 else f"step {r['success_step']}"

            lines.append(
                f"| {task_id} | {row['demo']} | {row['length']} | {ph['grasp']}, {ph['lift']}, {ph['carry/place']}, "
                f"{ph['release']} | {_sep(row, 'open_loop', '2cm')} | {_sep(row, 'open_loop', '5cm')} | "
                f"{_cm(close['ee_distance_m'])}, {_cm(close['ee_dxyz_m'][2])}, {close['orientation_error_rad']:.2f} | "
                f"{success(row['open_loop'])} | {success(row['open_loop_demo_rotation'])} | "
                f"{success(blind) if blind else '-'} | {_cm(row['replay']['ee_max_m'])} |")
    lines += ["", "| task | rollout | end-effector distance per phase, mean (cm): approach / grasp / lift / carry / "
              "release | joint error mean (rad) | lowest hand height (cm) | object lifted (cm) |",
              "|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        for name in ("open_loop", "open_loop_demo_rotation", "blind_plan"):
            rows = [r[name] for r in task["demos"] if name in r]
            if not rows:
                continue
            per_phase = " / ".join(
                _cm(np.mean([r["per_phase"][p]["ee_mean_m"] for r in rows if p in r["per_phase"]]))
                if any(p in r["per_phase"] for r in rows) else "-" for p in PHASES)
            lines.append(f"| {task_id} | {name} | {per_phase} | {np.mean([r['joint_mean_rad'] for r in rows]):.2f} | "
                         f"{', '.join(_cm(r['min_ee_height_m']) for r in rows)} | "
                         f"{', '.join(_cm(r['object_rise_max_m']) for r in rows)} |")
    lines += ["", "| task | action MSE: open loop vs demos / vs mean demo / demos' spread | per phase, open loop vs "
              "demos (approach, grasp, lift, carry, release) | inside the envelope (all 7 dims) | first exit step per "
              "dim (dx dy dz droll dpitch dyaw grip) | instruction effect steps 0-5 / 5-10 / 10-20: open loop, demos |",
              "|---|---|---|---|---|---|"]
    for task_id, task in report["tasks"].items():
        o = task["offline"]
        pp = o["per_phase"]["open_loop_mse_vs_demos"]
        eff = report.get("instruction_effect_by_task", {}).get(task_id) or o.get("instruction_effect", {})

        def windows(d):
            return " / ".join(f"{d[w]:.3f}" if w in d else "-" for w in ("0-5", "5-10", "10-20"))

        lines.append(
            f"| {task_id} | {o['open_loop_mse_vs_demos']:.3f} / {o['open_loop_mse_vs_mean_demo']:.3f} / "
            f"{o['demo_spread_mse']:.3f} | {', '.join(f'{pp[p]:.3f}' if p in pp else '-' for p in PHASES)} | "
            f"{o['inside_envelope_fraction_all_dims']:.0%} | "
            f"{' '.join(str(o['first_exit_step_per_dim'][str(k)]) for k in range(7))} | "
            f"{windows(eff.get('open_loop_vs_other_instructions', {}))}; "
            f"{windows(eff.get('mean_demo_vs_other_tasks', {}))} |")
    return "\n".join(lines) + "\n"
