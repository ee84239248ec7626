"""One dataset's screen of the demonstrations study (docs/research/demonstrations.md) on one page: every policy and
mode against every evaluation set, beside one of the dataset's demonstrations replayed blind on the same starts.

The study's sweep files name their evaluation cells `<model><mode><set>`: model `olt` (PredVLA `fit_sensory_olt`),
`table2` (PredVLA Table 2 literal), `B1`, `B2` (the BC baselines); mode `_open_loop` (exact open loop), none (Table
2's error regression) or `_carried` (error regression with its Adam carried), PredVLA only; set none (E1, official
init states), `_resets` (E2), `_placed_resets` (E2p) or `_shifted` (E3). The blind-replay folders are
`<blind>/<set>_<style>` as `predvla blind-replay` wrote them for the protocol; on E1 the plan's replay on its own
start (state 0) counts as that start's episode, so both figures cover official init states 0-9.

Command (from the repository root):

  python -m research.demonstration_sets --runs results/demonstrations/teleop_placed/runs \\
      --blind results/demonstrations/blind_replay --style teleop --out results/demonstrations/teleop_placed/sets

Writes OUT/sets.json, OUT/sets.md (successes/episodes per cell; a cell not run is "not run") and OUT/sets.png.

At full scale (all ten tasks), `--apart 2,3,6` also splits every cell and blind-replay figure into the listed tasks
(the screen's, whose episodes the screen already saw) and the others (sets.json's `apart`, a second table in sets.md),
from the records' per-task counts and the blind replays' per-task files:

  python -m research.demonstration_sets --runs results/demonstrations/teleop_full/runs \
      --blind results/demonstrations/blind_replay_full --style teleop --apart 2,3,6 \
      --out results/demonstrations/teleop_full/sets

Where a cell's episodes (`runs/eval/<cell>/`) and the blind replay's per-start outcomes (`<set>_<style>/tasks/`) both
exist, sets.json's `blind_overlap` also counts, per cell and set, the cell's successes on the starts where the
plan replayed blind succeeds too, beside the number chance would give (the cell's successes times the blind replay's
rate over the same starts): a policy that succeeds only where a blind replay does has not shown that it looks.
"""

import argparse
import json
import shlex
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

from lerobot_predvla.cli.demos import task_ids
from lerobot_predvla.report.formatting import fmt_rate, table
from lerobot_predvla.report.headline import load_blind_replay
from lerobot_predvla.report.results import ReportError, run_episodes
from lerobot_predvla.sims.libero import blind_replay
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text

SUITE = "libero_object"
# (name, cell-name suffix, what the starts are)
SETS = (("E1", "", "official init states"),
        ("E2", "_resets", "randomised resets of seed 3000"),
        ("E2p", "_placed_resets", "the resets, objects moved as in D3 (3 cm std)"),
        ("E3", "_shifted", "official init states, object to pick moved 4 cm"))
# (cell-name prefix, label)
POLICIES = (("olt_open_loop", "PredVLA fit_sensory_olt, exact open loop"),
            ("olt", "PredVLA fit_sensory_olt, Table 2's error regression"),
            ("olt_carried", "PredVLA fit_sensory_olt, error regression, Adam carried"),
            ("table2_open_loop", "PredVLA Table 2 literal, exact open loop"),
            ("table2", "PredVLA Table 2 literal, Table 2's error regression"),
            ("table2_carried", "PredVLA Table 2 literal, error regression, Adam carried"),
            ("B1", "BC-Transformer (B1)"),
            ("B2", "BC-RNN (B2)"))
NOT_RUN = "not run"
REPORT_JSON, REPORT_MD, FIGURE = "sets.json", "sets.md", "sets.png"
COMMAND = "python -m research.demonstration_sets"


def load_record(runs: Path, config: str, seed: int = 0) -> tuple[Path, dict | None]:
    """A cell's run record (checked to hold its totals) and its path; None when the cell has none."""
    path = runs / "records" / config / SUITE / f"seed{seed}.json"
    if not path.is_file():
        return path, None
    try:
        record = json.loads(path.read_text())
        int(record["successes"]), int(record["episodes"])
    except (ValueError, KeyError, TypeError) as err:
        raise ValueError(f"{path}: not a run record ({err}).") from err
    return path, record


def per_task(path: Path, record: dict) -> dict[int, tuple[int, int]]:
    """Task id -> (successes, episodes) of a run record."""
    try:
        return {int(t): (int(c["successes"]), int(c["episodes"])) for t, c in record["tasks"].items()}
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise ValueError(f"{path}: no per-task counts ({err}).") from err


def split(tasks: dict, listed: list[int], total: Callable[[dict], tuple[int, int]]) -> dict[str, tuple[int, int]]:
    """`total` of the entries of `tasks` (keyed by task id, int or str) in `listed`, and of the others."""
    return {group: total({t: v for t, v in tasks.items() if (int(t) in listed) == (group == "listed")})
            for group in ("listed", "others")}


def counts_total(tasks: dict[int, tuple[int, int]]) -> tuple[int, int]:
    return sum(s for s, _ in tasks.values()), sum(e for _, e in tasks.values())


def blind_tasks(blind: Path, set_name: str, style: str) -> dict[str, dict] | None:
    """Per task, the blind-replay report's entry of the dataset's plan from state 0 replayed blind on the set, None
    when not run (the report read and checked as the headline reads its blind replays)."""
    folder = blind / f"{set_name}_{style}"
    try:
        report = load_blind_replay(folder)
    except ReportError as err:
        raise ValueError(str(err)) from err
    if report is None:
        return None
    if SUITE not in report:
        raise ValueError(f"{folder / blind_replay.REPORT_JSON}: no {SUITE} blind replay.")
    return report[SUITE]


def blind_episodes(blind: Path, set_name: str, style: str) -> dict[tuple[str, int], bool] | None:
    """Per (task id, episode index), whether the state-0 plan replayed blind succeeds from that start (on E1 its own
    start, state 0, included), from the per-task files; None when the set has none."""
    folder = blind / f"{set_name}_{style}" / blind_replay.TASKS_DIR / SUITE
    found = {}
    for path in sorted(folder.glob("task*.json")):
        task = blind_replay.load_task(path)
        if task is None:
            raise ValueError(f"{path}: unreadable per-task result.")
        try:
            plan, task_id = task["plans"]["state0"], str(task["task_id"])
            found.update({(task_id, int(k)): step is not None for k, step in plan["success_step"].items()})
            if set_name == "E1":
                found[(task_id, int(plan["source_state"]))] = plan["source_replay_step"] is not None
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise ValueError(f"{path}: no per-start outcomes of the state-0 plan ({err!r}).") from err
    return found or None


def overlap(episodes: dict[tuple[str, int], bool], blind: dict[tuple[str, int], bool]) -> dict | None:
    """On the starts both ran: the cell's successes, those where the blind replay succeeds too, and the number
    chance would give; None when they share no start."""
    keys = episodes.keys() & blind.keys()
    if not keys:
        return None
    successes = sum(episodes[k] for k in keys)
    blind_rate = sum(blind[k] for k in keys) / len(keys)
    return {"starts": len(keys), "successes": successes, "with_blind": sum(episodes[k] and blind[k] for k in keys),
            "by_chance": round(successes * blind_rate, 2)}


def blind_total(tasks: dict[str, dict], set_name: str) -> tuple[int, int]:
    """(successes, episodes) of the tasks' plans: on E1 with each plan's replay on its own start (state 0)."""
    return blind_replay.totals_with_source(tasks) if set_name == "E1" else blind_replay.totals(tasks)


def collect(runs: Path, blind: Path, style: str, apart: list[int] | None = None) -> dict:
    """sets.json's content: per policy label and set name, [successes, episodes] or None; with `apart`, the same
    per group of tasks (`listed`, `others`) under `apart`; `blind_overlap` where episodes and per-start blind
    outcomes exist (`overlap`)."""
    if not (runs / "records").is_dir():
        raise ValueError(f"--runs {runs}: no records/ folder (a `predvla sweep --runs-dir`).")
    cells: dict[str, dict] = {}
    cells_apart: dict[str, dict] = {}
    for prefix, label in POLICIES:
        cells[label], cells_apart[label] = {}, {}
        for name, suffix, _ in SETS:
            path, record = load_record(runs, prefix + suffix)
            cells[label][name] = None if record is None else (int(record["successes"]), int(record["episodes"]))
            if apart:
                cells_apart[label][name] = None if record is None else split(per_task(path, record), apart,
                                                                             counts_total)
    figures, figures_apart = {}, {}
    for name, _, _ in SETS:
        tasks = blind_tasks(blind, name, style)
        figures[name] = None if tasks is None else blind_total(tasks, name)
        if apart:
            figures_apart[name] = None if tasks is None else split(tasks, apart, partial(blind_total, set_name=name))
    report = {"style": style, "sets": {name: what for name, _, what in SETS}, "cells": cells,
              "blind_replay": figures}
    blind_starts = {name: blind_episodes(blind, name, style) for name, _, _ in SETS}
    overlaps = {label: {name: overlap(run_episodes(runs, prefix + suffix, SUITE, 0), blind_starts[name])
                        for name, suffix, _ in SETS if blind_starts[name] and cells[label][name]}
                for prefix, label in POLICIES}
    overlaps = {label: {name: o for name, o in sets.items() if o} for label, sets in overlaps.items()}
    if any(overlaps.values()):
        report["blind_overlap"] = {label: sets for label, sets in overlaps.items() if sets}
    if apart:
        report["apart"] = {"tasks": sorted(apart), "cells": cells_apart, "blind_replay": figures_apart}
    return report


def markdown(report: dict, command: str) -> str:
    def text(value) -> str:
        return fmt_rate(*value) if value else NOT_RUN

    def split(value) -> str:
        return f"{text(value['listed'])} / {text(value['others'])}" if value else NOT_RUN

    header = ["policy", *[f"{name}: {what}" for name, what in report["sets"].items()]]
    reference = f"reference: one {report['style']} demonstration replayed blind (plan from official init state 0)"
    body = [[label, *[text(v) for v in sets.values()]] for label, sets in report["cells"].items()]
    body.append([reference, *[text(v) for v in report["blind_replay"].values()]])
    lines = ["# Success per evaluation set", "",
             "Success in % (successes/episodes) of every cell, per evaluation set, with one of the dataset's "
             "demonstrations replayed blind on the same starts.", "", table(header, body), ""]
    if apart := report.get("apart"):
        listed = ", ".join(map(str, apart["tasks"]))
        body = [[label, *[split(v) for v in sets.values()]] for label, sets in apart["cells"].items()]
        body.append([reference, *[split(v) for v in apart["blind_replay"].values()]])
        lines += [f"The same cells on tasks {listed} / on the other tasks:", "", table(header, body), ""]
    if overlaps := report.get("blind_overlap"):
        body = [[label, *[overlap_text(sets.get(name)) for name in report["sets"]]] for label, sets in overlaps.items()]
        lines += ["Each cell's successes on the starts where the plan replayed blind succeeds too, of its successes "
                  "(by chance: its successes times the blind replay's rate on the same starts):", "",
                  table(header, body), ""]
    return "\n".join([*lines, "Reproduce:", "", "```bash", command, "```", ""])


def overlap_text(value: dict | None) -> str:
    return f"{value['with_blind']} of {value['successes']} (by chance {value['by_chance']:.1f})" if value else "-"


def figure(report: dict, path: Path) -> None:
    """Grouped bars, one group per evaluation set, each bar's successes/episodes above it (× where not run), and
    the blind replay's success as a dashed line across its group."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    sets, labels = list(report["sets"]), list(report["cells"])
    colors = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(12, 4.8))
    width = 0.8 / len(labels)
    for i, label in enumerate(labels):
        for j, name in enumerate(sets):
            value, x = report["cells"][label][name], j + (i - (len(labels) - 1) / 2) * width
            if value:
                height = 100 * value[0] / value[1]
                ax.bar(x, height, width, color=colors(i))
                ax.text(x, height + 1, f"{value[0]}/{value[1]}", ha="center", va="bottom", fontsize=6, rotation=90)
            else:
                ax.text(x, 1, "×", ha="center", va="bottom", fontsize=8, color=colors(i))
    for j, name in enumerate(sets):
        if value := report["blind_replay"][name]:
            ax.hlines(100 * value[0] / value[1], j - 0.45, j + 0.45, colors="black", linestyles="--")
    ax.set_xticks(range(len(sets)), [f"{name}: {report['sets'][name]}".replace(", ", ",\n") for name in sets],
                  fontsize=8)
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 115)
    ax.set_title(f"Success per evaluation set, {report['style']} demonstrations (× not run)")
    handles = [Patch(color=colors(i), label=label) for i, label in enumerate(labels)]
    handles.append(Line2D([], [], color="black", linestyle="--", label="one demonstration replayed blind"))
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    atomic_save_figure(fig, path)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="the sweep's --runs-dir")
    parser.add_argument("--blind", type=Path, required=True, help="folder of the <set>_<style> blind replays")
    parser.add_argument("--style", choices=("scripted", "teleop"), required=True, help="the dataset's style")
    parser.add_argument("--apart", type=task_ids, default=None,
                        help="task ids, e.g. 2,3,6: also every figure on these tasks and on the others")
    parser.add_argument("--out", type=Path, required=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
    try:
        report = collect(args.runs, args.blind, args.style, args.apart)
    except ValueError as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / REPORT_JSON, report)
    atomic_write_text(args.out / REPORT_MD, markdown(report, f"{COMMAND} {shlex.join(argv)}"))
    figure(report, args.out / FIGURE)
    print((args.out / REPORT_MD).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
