"""The figures of a report: the ladder, trainable parameters against success (beside published points), the
sensory ablations per task, the corruption curves and success per task. Each returns False, drawing nothing, when
the report has nothing to show in it."""

from pathlib import Path

import numpy as np

from lerobot_predvla.report.paired import paired_task_rates
from lerobot_predvla.report.results import Results, task_ids
from lerobot_predvla.report.tables import ladder_rungs, task_table
from lerobot_predvla.sims.libero.protocol import SHORT_SUITES, SUITE_LABELS
from lerobot_predvla.utils.io import atomic_save_figure

FIGURES = {
    "ladder": "ladder.png",
    "params": "params_vs_success.png",
    "pertask": "ablation_pertask.png",
    "corruption": "corruption.png",
    "tasks": "success_per_task.png",
}
# Published LIBERO 4-suite means for context (trainable parameters, mean success %); not a controlled comparison.
PUBLISHED_REFERENCES = (
    ("OpenVLA", 7.0e9, 76.5),
    ("Octo", 93e6, 75.1),
    ("SmolVLA", 0.45e9, 87.3),
    ("pi0", 3.3e9, 94.15),
    ("PredVLA (paper)", 675_732, 75.35),
)
PARAMETERLESS_REFERENCES = (("Diffusion Policy", 72.4),)  # its parameter count is not given with the result


def _save(fig, path: Path) -> None:
    atomic_save_figure(fig, path, dpi=130, bbox_inches="tight")


def ladder_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    configs = summary["configs"]
    chain, branches = ladder_rungs(summary)
    if not chain:
        return False
    short = [s for s in SHORT_SUITES if s in summary["suites"]]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    x = {n: i for i, n in enumerate(chain)}
    colors = dict(zip(short, ("tab:blue", "tab:orange", "tab:green"), strict=False))

    def value(n: str, s: str | None) -> float:
        v = configs[n]["mean3"] if s is None else configs[n]["suites"][s]["mean"]
        return np.nan if v is None else v

    for s in [*short, None]:
        style = (
            {"color": "black", "linewidth": 3, "label": "3-suite mean"}
            if s is None
            else {"color": colors[s], "linewidth": 1.2, "label": SUITE_LABELS[s]}
        )
        ax.plot(range(len(chain)), [value(n, s) for n in chain], marker="o", **style)
        for b in branches:
            parent = configs[b].get("paired_against")
            if parent in x:
                bx = x[parent] + 0.5
                ax.plot(
                    [x[parent], bx],
                    [value(parent, s), value(b, s)],
                    linestyle="--",
                    marker="s",
                    color=style["color"],
                    linewidth=style["linewidth"] * 0.7,
                )
                if s is None:
                    ax.annotate(b, (bx, value(b, s)), textcoords="offset points", xytext=(5, -10))
    ax.set_xticks(range(len(chain)), chain)
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(0, 100)
    ax.set_title("Ladder: PredVLA to BC-RNN (dashed: side branches)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def params_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    four = "libero_10" in summary["suites"]
    key = "mean4" if four else "mean3"
    ours = [
        (n, c["params"], c[key])
        for n, c in summary["configs"].items()
        if c["group"] in ("main", "baseline") and c["params"] and c[key] is not None
    ]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    baseline_params = [c["params"] for c in summary["configs"].values() if c["group"] == "baseline" and c["params"]]
    if baseline_params:
        ax.axvspan(
            min(baseline_params) * 0.95,
            max(baseline_params) * 1.05,
            color="gray",
            alpha=0.15,
            label="controlled baselines (params range)",
        )
    for i, (name, params, success) in enumerate(PUBLISHED_REFERENCES):
        ax.scatter(params, success, marker="^", color="tab:gray", label="published (reported)" if i == 0 else None)
        ax.annotate(name, (params, success), textcoords="offset points", xytext=(5, 4), fontsize=8)
    for name, success in PARAMETERLESS_REFERENCES:
        ax.axhline(success, color="tab:gray", linestyle=":", linewidth=1)
        ax.annotate(
            f"{name} {success} (params not reported)",
            (1e7, success),
            textcoords="offset points",
            xytext=(0, -11),
            fontsize=8,
            color="tab:gray",
        )
    for i, (name, params, success) in enumerate(ours):
        ax.scatter(params, success, marker="o", color="tab:red", zorder=3, label="this sweep" if i == 0 else None)
        ax.annotate(name, (params, success), textcoords="offset points", xytext=(5, -10), fontsize=8, color="tab:red")
    ax.set_xscale("log")
    ax.set_xlim(1e5, 2e10)
    ax.set_ylim(0, 100)
    ax.set_xlabel("trainable policy parameters")
    ax.set_ylabel(f"LIBERO mean success (%) — ours: {'4' if four else '3'}-suite mean")
    ax.set_title("Parameters vs success (published points: reported numbers, not controlled)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="lower right", fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def sensory_ablations(results: Results) -> list[tuple[str, str]]:
    """(config, channel) of the error-channel ablations: eval overrides setting er_lambda_v / er_lambda_q to 0."""
    found = []
    for name, c in results.configs.items():
        overrides = c.get("eval_overrides") or {}
        for field, channel in (("er_lambda_v", "visual"), ("er_lambda_q", "proprioceptive")):
            if field in overrides and float(overrides[field]) == 0.0:
                found.append((name, channel))
    return found


def pertask_figure(results: Results, summary: dict, path: Path) -> bool:
    """Per task: the intact model's success (gray) and each sensory ablation's change (colored), on the episodes
    both ran from the same starts where the episodes are recorded (an ablation may run fewer per task than the
    intact model), else the difference of the seeds' per-task rates."""
    import matplotlib.pyplot as plt

    ablations = sensory_ablations(results)
    reference = results.reference()
    if not ablations or reference is None:
        return False
    suites = [s for s in results.suites() if any(results.tasks.get(a, {}).get(s) for a, _ in ablations)]
    if not suites:
        return False
    fig, axes = plt.subplots(1, len(suites), figsize=(5 * len(suites), 4), squeeze=False)
    colors = ("tab:blue", "tab:orange")
    for ax, suite in zip(axes[0], suites, strict=True):
        intact = results.tasks.get(reference, {}).get(suite, {})
        task_ids = sorted({t for seed in intact.values() for t in seed}, key=int)
        base = [np.mean([intact[s][t] for s in intact]) if intact else np.nan for t in task_ids]
        deltas = []
        same_episodes = False  # whether the gray bars are the intact model's success on the first ablation's pairs
        for i, (name, _) in enumerate(ablations):
            paired = paired_task_rates(summary, name, reference, suite)
            if paired is not None:
                deltas.append([paired[t][1] if t in paired else np.nan for t in task_ids])
                if i == 0:
                    base = [paired[t][0] if t in paired else np.nan for t in task_ids]
                    same_episodes = True
                continue
            runs = results.tasks.get(name, {}).get(suite, {})
            seeds = sorted(set(runs) & set(intact))
            deltas.append([np.mean([runs[s][t] - intact[s][t] for s in seeds]) if seeds else np.nan for t in task_ids])
        order = np.argsort(np.nan_to_num(deltas[0], nan=0.0))
        xs = np.arange(len(task_ids))
        width = 0.8 / (1 + len(ablations))
        intact_label = f"{reference} (intact{', same episodes' if same_episodes else ''})"
        ax.bar(xs, np.asarray(base)[order], width, color="lightgray", label=intact_label)
        for i, ((name, channel), delta) in enumerate(zip(ablations, deltas, strict=True)):
            ax.bar(
                xs + (i + 1) * width,
                np.asarray(delta)[order],
                width,
                color=colors[i % 2],
                label=f"{name}: change without {channel} error",
            )
        ax.axhline(0, color="black", linewidth=0.8)
        ax.set_xticks(xs + width * len(ablations) / 2, [task_ids[i] for i in order])
        ax.set_xlabel("task id (sorted by the first ablation's change)")
        ax.set_title(SUITE_LABELS[suite])
        ax.set_ylim(-100, 100)
    axes[0][0].set_ylabel("success (%) / change (points)")
    axes[0][-1].legend(fontsize=7, loc="lower right")
    _save(fig, path)
    plt.close(fig)
    return True


def corruption_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    configs = summary["configs"]
    names = [n for n, c in configs.items() if c["group"] == "corruption" and c.get("corruption")]
    if not names:
        return False
    suites = [s for s in summary["suites"] if any(configs[n]["suites"][s]["n"] for n in names)]
    if not suites:
        return False
    fig, axes = plt.subplots(1, len(suites), figsize=(4.5 * len(suites), 3.8), squeeze=False)
    channels = sorted({configs[n]["corruption"].get("channel") for n in names})
    for ax, suite in zip(axes[0], suites, strict=True):
        for channel, color in zip(channels, ("tab:blue", "tab:orange", "tab:green"), strict=False):
            points = []
            for n in names:
                spec = configs[n]["corruption"]
                cell = configs[n]["suites"][suite]
                if spec.get("channel") == channel and cell["n"]:
                    points.append((float(spec["alpha"]), cell["mean"], cell["std"]))
            intact = configs.get(configs[names[0]].get("paired_against") or "", {}).get("suites", {}).get(suite)
            if intact and intact["n"]:
                points.append((0.0, intact["mean"], intact["std"]))
            points.sort()
            if points:
                a, m, sd = (np.asarray(v) for v in zip(*points, strict=True))
                ax.plot(a, m, marker="o", color=color, label=str(channel))
                ax.fill_between(a, m - sd, m + sd, color=color, alpha=0.2)
        open_loop = {configs[n]["corruption"].get("open_loop") for n in names} - {None}
        for ref in open_loop:
            cell = configs.get(ref, {}).get("suites", {}).get(suite)
            if cell and cell["n"]:
                ax.axhline(cell["mean"], color="black", linestyle="--", linewidth=1, label=f"open loop ({ref})")
        ax.set_xlabel("α (fraction of observations replaced)")
        ax.set_title(SUITE_LABELS[suite])
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success rate (%)")
    axes[0][-1].legend(fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def task_figure(results: Results, path: Path) -> bool:
    """Per task of every multi-task suite: each configuration's success, side by side."""
    import matplotlib.pyplot as plt

    suites = [s for s in results.suites() if task_table(results, s) is not None]
    if not suites:
        return False
    fig, axes = plt.subplots(len(suites), 1, figsize=(10, 3.6 * len(suites)), squeeze=False)
    for ax, suite in zip(axes[:, 0], suites, strict=True):
        names = [n for n in results.configs if results.tasks.get(n, {}).get(suite)]
        ids = task_ids(results, suite)
        width = 0.8 / len(names)
        for i, name in enumerate(names):
            seeds = results.tasks[name][suite]
            values = [np.mean([seeds[s][t] for s in seeds if t in seeds[s]] or [np.nan]) for t in ids]
            ax.bar(np.arange(len(ids)) + i * width, values, width, label=results.configs[name].get("label") or name)
        ax.set_xticks(np.arange(len(ids)) + width * (len(names) - 1) / 2, ids)
        ax.set_xlabel("task id")
        ax.set_ylabel("success (%)")
        ax.set_ylim(0, 100)
        ax.set_title(SUITE_LABELS[suite])
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].legend(fontsize=7, ncol=2)
    _save(fig, path)
    plt.close(fig)
    return True
