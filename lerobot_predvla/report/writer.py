"""`predvla report RUNS_DIR --out REPORT_DIR`: `report.md` (Markdown tables and figures, readable on GitHub),
`report.json` (the aggregates, read by `predvla push --results`) and the PNG figures."""

from pathlib import Path

from lerobot_predvla.report.figures import (
    FIGURES,
    corruption_figure,
    ladder_figure,
    params_figure,
    pertask_figure,
    task_figure,
)
from lerobot_predvla.report.formatting import MISSING
from lerobot_predvla.report.paired import paired_episodes, pairs_apart
from lerobot_predvla.report.results import SUMMARY_FILE, Results, load_plan, load_records
from lerobot_predvla.report.robustness import (
    ROBUSTNESS_FIGURE,
    blind_line,
    robustness_figure,
    robustness_pairs_table,
    robustness_table,
)
from lerobot_predvla.report.sections import (
    START_SPREAD_FILE,
    fresh_clone_section,
    lr_selection_section,
    mechanism_section,
    stages_section,
    starts_section,
)
from lerobot_predvla.report.summary import summarize
from lerobot_predvla.report.tables import (
    ablation_table,
    apart_table,
    baseline_table,
    corruption_table,
    episodes_table,
    ladder_table,
    main_table,
    paper_table,
    task_table,
)
from lerobot_predvla.sims.libero.protocol import SUITE_LABELS
from lerobot_predvla.utils.io import atomic_write_json, atomic_write_text

REPORT_FILE = "report.md"


def write_report(
    runs_dir: Path, out: Path, blind_replays: list[Path] = (), tasks_apart: list[int] | None = None
) -> dict:
    """Build tables, figures, `report.md` and `report.json` in `out`; returns the summary. `blind_replays`: reports
    of `predvla blind-replay` (one object shift each) drawn beside the robustness runs. `tasks_apart`: task ids whose
    paired episodes are also counted apart from the other tasks' (e.g. the tasks a screen chose settings on)."""
    import matplotlib

    matplotlib.use("Agg")
    records = load_records(runs_dir)
    results = Results.build(records, load_plan(runs_dir))
    summary = summarize(results)
    blind = blind_line(blind_replays)
    if blind:
        summary["blind_replay"] = {suite: [[cm, successes, episodes] for cm, successes, episodes in points]
                                   for suite, points in blind.items()}
    paired_episodes(summary, records, Path(runs_dir))
    if tasks_apart:
        pairs_apart(summary, tasks_apart)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    made = {
        "ladder": ladder_figure(summary, out / FIGURES["ladder"]),
        "params": params_figure(summary, out / FIGURES["params"]),
        "pertask": pertask_figure(results, summary, out / FIGURES["pertask"]),
        "corruption": corruption_figure(summary, out / FIGURES["corruption"]),
        "tasks": task_figure(results, out / FIGURES["tasks"]),
    }
    summary["figures"] = {k: FIGURES[k] for k, ok in made.items() if ok}
    if robustness_figure(records, out / ROBUSTNESS_FIGURE, blind):
        summary["figures"]["robustness"] = ROBUSTNESS_FIGURE
    missing = [
        f"{name}/{suite}/seed{seed}"
        for name, c in summary["configs"].items()
        for suite, cell in c["suites"].items()
        for seed in cell["missing_seeds"]
    ]
    summary["missing_runs"] = missing
    sections = [
        "# PredVLA experiment report",
        "",
        f"{len(records)} runs from `{runs_dir}`; protocol: {summary['protocol']}. Success rates in %, mean ± "
        f"standard deviation across seeds (n = 1: a single seed); {MISSING} marks a missing result, (k/n seeds) a "
        "partial one.",
    ]
    for title, table, figure, note in (
        ("Main results", main_table(summary), None, "3-suite mean: spatial, goal, object; 4-suite adds long."),
        ("Controlled baselines", baseline_table(summary), None, "Mean over the suites shown."),
        (
            "Beside the paper",
            paper_table(summary),
            None,
            "The paper's published success of the same configuration (its Tables 3-6: mean ± standard deviation over "
            "its seeds) beside ours.",
        ),
        (
            "Trainable parameters vs success",
            None,
            "params",
            "Published points are reported numbers with different protocols, for scale only.",
        ),
        (
            "Ladder",
            ladder_table(summary),
            "ladder",
            "Δ: change in the 3-suite mean relative to the preceding rung (side branches: relative to their parent).",
        ),
        (
            "Ablations",
            ablation_table(summary),
            "pertask",
            "Δ: success minus that of the run named (its `compare_to`, else the intact model), mean over the seeds "
            "both have (n), each run's rate over its own episodes; where the two ran different numbers of episodes, "
            "the paired episodes below compare only those both ran.",
        ),
        (
            "Paired episodes",
            episodes_table(summary),
            None,
            "Each episode against the same start of the compared run (same evaluation seed, resets and protocol); "
            "sign test: exact, two-sided, on the episodes that succeed in only one.",
        ),
        (
            "Paired episodes, tasks apart",
            apart_table(summary),
            None,
            "The pairs above counted on the tasks named by `--tasks-apart` and on the other tasks separately, each "
            "with its own sign test.",
        ),
        (
            "Robustness: shifted objects and LIBERO-PRO / LIBERO-plus variants",
            "\n\n".join(t for t in (robustness_table(records, runs_dir, blind),
                                    robustness_pairs_table(records, summary)) if t) or None,
            "robustness",
            "Success in % (successes/episodes, pooled over seeds) per condition: the object to pick shifted by the "
            "distance shown from each official init state, or a LIBERO-PRO / LIBERO-plus variant of the suite; "
            "unsettled: episodes whose shifted object did not rest where it was put (docs/evaluation.md), and "
            "settled: the success without them (n/a: the run's record does not name them). Then each configuration "
            "with `compare_to` against the run it names, episode by episode from the same starts: pairs that succeed "
            "in both, in only one, in neither, and the exact two-sided sign test on those that succeed in only one; "
            "once over all pairs, once without the pairs whose shifted object did not settle in either run.",
        ),
        (
            "Corrupted observations",
            corruption_table(summary),
            "corruption",
            "α: fraction of observations replaced; bands ±1 seed standard deviation; dashed: open loop.",
        ),
        *[
            (
                f"Per task: {SUITE_LABELS[suite]}",
                task_table(results, suite),
                "tasks" if i == 0 else None,
                "Success per task (%), mean over seeds.",
            )
            for i, suite in enumerate(s for s in results.suites() if task_table(results, s) is not None)
        ],
    ):
        has_figure = figure in summary["figures"]
        if table is None and not has_figure:
            continue
        sections += ["", f"## {title}", "", note]
        if table is not None:
            sections += ["", table]
        if has_figure:
            sections += ["", f"![{title}]({summary['figures'][figure]})"]
    sections += starts_section(out / START_SPREAD_FILE) + mechanism_section(out) + lr_selection_section(runs_dir)
    stages = stages_section(records, runs_dir)
    if stages:
        sections += ["", "## Stages: wall time and commands", "", *stages]
    sections += fresh_clone_section(runs_dir)
    if missing:
        sections += [
            "",
            "## Missing runs",
            "",
            f"{len(missing)} planned runs have no record:",
            "",
            *[f"- `{m}`" for m in missing],
        ]
    atomic_write_text(out / REPORT_FILE, "\n".join(sections) + "\n")
    atomic_write_json(out / SUMMARY_FILE, summary)
    return summary
