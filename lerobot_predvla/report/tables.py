"""The Markdown tables of a report, from its summary (`summary.summarize`, with the paired episodes) or, per task,
from its `Results`: main results, controlled baselines, the paper's numbers beside ours, the ladder, ablations,
paired episodes, corrupted observations and success per task."""

import numpy as np

from lerobot_predvla.report.formatting import MISSING, fmt_mean_std, fmt_num, fmt_params, table
from lerobot_predvla.report.paired import paired_entries
from lerobot_predvla.report.results import Results, task_ids
from lerobot_predvla.sims.libero.protocol import SHORT_SUITES, SUITE_LABELS


def fmt_cell(cell: dict) -> str:
    """A summary cell: mean ± std over its seeds, `(k/n seeds)` when planned seeds lack a result."""
    if cell["n"] == 0:
        return f"{MISSING} (0/{cell['planned']})" if cell["planned"] else MISSING
    text = fmt_mean_std(cell["mean"], cell["std"], cell["n"])
    return text + (f" ({cell['n']}/{cell['planned']} seeds)" if cell["n"] < cell["planned"] else "")


def _label(summary: dict, name: str) -> str:
    return summary["configs"][name].get("label") or name


def main_table(summary: dict) -> str | None:
    names = [n for n, c in summary["configs"].items() if c["group"] == "main"]
    if not names:
        return None
    suites = summary["suites"]
    short = [s for s in SHORT_SUITES if s in suites]
    header = ["Model", "Params", *[SUITE_LABELS[s] for s in short], "3-suite mean"]
    if "libero_10" in suites:
        header += ["long", "4-suite mean"]
    rows = []
    last_of = _pools_after(summary, names)
    for n in names:
        c = summary["configs"][n]
        for label, params, cells in (
            (_label(summary, n), c["params"], c),
            *(
                [
                    (
                        _pooled_label(summary, last_of[n]),
                        summary["configs"][last_of[n]]["params"],
                        summary["pooled"][last_of[n]],
                    )
                ]
                if n in last_of
                else []
            ),
        ):
            row = [label, fmt_params(params), *[fmt_cell(cells["suites"][s]) for s in short], fmt_num(cells["mean3"])]
            if "libero_10" in suites:
                row += [fmt_cell(cells["suites"]["libero_10"]), fmt_num(cells["mean4"])]
            rows.append(row)
    return table(header, rows)


def _pools_after(summary: dict, names: list[str]) -> dict[str, str]:
    """`{name: pool target}`: a pool's row (pool_with) follows the last of its configurations in a table of `names`."""
    return {
        [n for n in names if n in pool["configs"]][-1]: target
        for target, pool in summary.get("pooled", {}).items()
        if target in names
    }


def _pooled_label(summary: dict, target: str) -> str:
    """The row of a pool: its target's label and every configuration whose seeds it gathers."""
    return f"{_label(summary, target)}, pooled seeds ({' + '.join(summary['pooled'][target]['configs'])})"


def paper_table(summary: dict) -> str | None:
    """Every configuration with a published number (the sweep file's `paper`) beside ours, per suite."""
    rows = []
    pooled = summary.get("pooled", {})
    for name, c in summary["configs"].items():
        for suite, value in c.get("paper", {}).items():
            mean, std = (value + [None])[:2] if isinstance(value, list) else (value, None)
            # A pool's target stands for all its seeds (pool_with): its row sets them beside the paper's seeds.
            ours = (pooled[name] if name in pooled else c)["suites"].get(suite)
            label = _pooled_label(summary, name) if name in pooled else _label(summary, name)
            rows.append(
                [
                    label,
                    SUITE_LABELS[suite],
                    fmt_cell(ours) if ours else MISSING,
                    fmt_mean_std(mean, std),
                    fmt_num(ours["mean"] - mean if ours and ours["mean"] is not None else None, signed=True),
                ]
            )
    return table(["Model", "suite", "ours", "paper", "ours − paper"], rows) if rows else None


def baseline_table(summary: dict) -> str | None:
    names = [n for n, c in summary["configs"].items() if c["group"] == "baseline"]
    if not names:
        return None
    ref = summary["reference"]
    ref_params = summary["configs"][ref]["params"] if ref else None
    suites = summary["suites"]
    rows = []
    for n in [*names, *([ref] if ref else [])]:
        c = summary["configs"][n]
        ratio = f"{c['params'] / ref_params:.3f}×" if c["params"] and ref_params else MISSING
        mean = c["mean4"] if "libero_10" in suites else c["mean3"]
        rows.append(
            [
                n if n != ref else "—",
                _label(summary, n) + (" (ours)" if n == ref else ""),
                fmt_params(c["params"]),
                ratio,
                *[fmt_cell(c["suites"][s]) for s in suites],
                fmt_num(mean),
            ]
        )
    return table(["", "Model", "Params", "vs. ours", *[SUITE_LABELS[s] for s in suites], "Mean"], rows)


def ladder_rungs(summary: dict) -> tuple[list[str], list[str]]:
    """(main chain starting at the intact model, side branches) of the ladder; empty without ladder configs."""
    configs = summary["configs"]
    ladder = [n for n, c in configs.items() if c["group"] == "ladder"]
    if not ladder:
        return [], []
    ref = summary["reference"]
    chain = ([ref] if ref and ref not in ladder else []) + [n for n in ladder if not configs[n]["branch"]]
    return chain, [n for n in ladder if configs[n]["branch"]]


def ladder_table(summary: dict) -> str | None:
    chain, branches = ladder_rungs(summary)
    if not chain:
        return None
    short = [s for s in SHORT_SUITES if s in summary["suites"]]
    ordered = chain + branches
    rows = []
    for n in ordered:
        c = summary["configs"][n]
        delta = fmt_num(c.get("delta_mean3"), signed=True) if c.get("paired_against") else MISSING
        rows.append(
            [
                n,
                _label(summary, n),
                fmt_params(c["params"]),
                *[fmt_cell(c["suites"][s]) for s in short],
                fmt_num(c["mean3"]),
                delta,
            ]
        )
    return table(["", "Modification", "Params", *[SUITE_LABELS[s] for s in short], "Mean", "Δ"], rows)


def ablation_table(summary: dict) -> str | None:
    names = [n for n, c in summary["configs"].items() if c["group"] == "ablation"]
    if not names:
        return None
    suites = summary["suites"]
    rows = []
    last_of = _pools_after(summary, names)
    for n in names:
        c = summary["configs"][n]
        rows.append([n, _label(summary, n), *[fmt_cell(c["suites"][s]) for s in suites]])
        paired = c.get("paired", {})
        deltas = []
        for s in suites:
            p = paired.get(s)
            deltas.append(MISSING if not p or p["n"] == 0 else f"{p['delta']:+.2f} (n={p['n']})")
        rows.append(["", f"  Δ vs {c.get('paired_against', MISSING)} (paired seeds)", *deltas])
        if n in last_of:
            pool = summary["pooled"][last_of[n]]
            rows.append(["", _pooled_label(summary, last_of[n]), *[fmt_cell(pool["suites"][s]) for s in suites]])
    return table(["", "Change from PredVLA", *[SUITE_LABELS[s] for s in suites]], rows)


def corruption_table(summary: dict) -> str | None:
    names = [n for n, c in summary["configs"].items() if c["group"] == "corruption" and c.get("corruption")]
    if not names:
        return None
    suites = [s for s in summary["suites"] if any(summary["configs"][n]["suites"][s]["n"] for n in names)]
    rows = []
    for n in sorted(
        names,
        key=lambda n: (
            summary["configs"][n]["corruption"].get("channel", ""),
            summary["configs"][n]["corruption"].get("alpha", 0),
        ),
    ):
        c = summary["configs"][n]
        rows.append(
            [
                n,
                str(c["corruption"].get("channel")),
                str(c["corruption"].get("alpha")),
                *[fmt_cell(c["suites"][s]) for s in suites],
            ]
        )
    return table(["", "channel", "α", *[SUITE_LABELS[s] for s in suites]], rows)


PAIR_HEADERS = ["episode pairs", "successes (model / against)", "only model / only against", "sign test p"]


def pair_cells(counts: dict) -> list[str]:
    """The PAIR_HEADERS cells of a set of episode pairs (`with_sign_test`)."""
    return [
        str(counts["pairs"]),
        f"{counts['successes']} / {counts['against_successes']}",
        f"{counts['only']} / {counts['only_against']}",
        f"{counts['sign_test_p']:.3g}",
    ]


def episodes_table(summary: dict) -> str | None:
    """Paired episodes of every `compare_to` pair, then of every pool over its seeds (`pool_with`) or evaluation
    sets (`pool_sets`) together."""
    rows = [
        [name, e["against"], SUITE_LABELS[suite], ", ".join(map(str, e["seeds"])), *pair_cells(e)]
        for name, episodes in paired_entries(summary)
        for suite in summary["suites"]
        if (e := episodes.get(suite))
    ]
    notes = [
        f"Not paired: `{u['config']}` against `{u['against']}`, {SUITE_LABELS[u['suite']]}, seed {u['seed']}: "
        "both load one checkpoint path, but not the same weights (`model_sha256` of their records differs; a "
        "training redone in place). Evaluate both from the new checkpoint to pair them."
        for u in summary.get("unpaired", [])
    ]
    if not rows and not notes:
        return None
    parts = (
        [
            table(
                ["Model", "against", "suite", "seeds", *PAIR_HEADERS],
                rows,
            )
        ]
        if rows
        else []
    )
    return "\n\n".join(parts + notes)


def apart_table(summary: dict) -> str | None:
    """The paired episodes of every `compare_to` pair and pool, on the tasks of `--tasks-apart` and on the other
    tasks (`pairs_apart`); None without `--tasks-apart`."""
    if "tasks_apart" not in summary:
        return None
    named = ", ".join(map(str, summary["tasks_apart"]))
    rows = [
        [name, e["against"], SUITE_LABELS[suite], f"tasks {named}" if group == "tasks" else "the other tasks",
         *pair_cells(g)]
        for name, episodes in paired_entries(summary)
        for suite in summary["suites"]
        if (e := episodes.get(suite))
        for group, g in e["apart"].items()
    ]
    if not rows:
        return None
    return table(
        ["Model", "against", "suite", "tasks", *PAIR_HEADERS],
        rows,
    )


def task_table(results: Results, suite: str) -> str | None:
    """Success per task (mean over seeds, %) of every configuration evaluated on `suite`."""
    names = [n for n in results.configs if results.tasks.get(n, {}).get(suite)]
    ids = task_ids(results, suite)
    if not names or len(ids) < 2:
        return None
    rows = []
    for name in names:
        seeds = results.tasks[name][suite]
        rows.append(
            [
                name,
                *[
                    fmt_num(np.mean([seeds[s][t] for s in seeds if t in seeds[s]]))
                    if any(t in seeds[s] for s in seeds)
                    else MISSING
                    for t in ids
                ],
                fmt_num(np.mean([results.rates[name][suite][s] for s in seeds])),
            ]
        )
    return table(["Model", *[f"task {t}" for t in ids], "mean"], rows)
