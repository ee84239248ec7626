"""The four-suite headline table of README.md and docs/results.md: this project's four-suite sweep
(configs/sweeps/libero_four_suites.yaml) per suite beside the paper's Table 3 (PredVLA with error regression,
BC-Transformer, BC-RNN, published in configs/sweeps/paper.yaml), the paper's exact open loop (Table 6, A6) and one
demonstration replayed blind (`predvla blind-replay`), with the 3-suite (spatial, goal, object) and 4-suite means of
the suite means. The table exists once `results/libero_four_suites/report.json` is committed; before that the
headline shows libero_object alone."""

from pathlib import Path

from lerobot_predvla.columns import SUITES
from lerobot_predvla.report.formatting import MISSING, fmt_mean_std, fmt_num, fmt_rate, table
from lerobot_predvla.report.results import SUMMARY_FILE, ReportError, load_summary
from lerobot_predvla.report.summary import suites_mean
from lerobot_predvla.report.tables import fmt_cell
from lerobot_predvla.sims.libero import blind_replay
from lerobot_predvla.sims.libero.protocol import PAPER_OPEN_LOOP, SHORT_SUITES, SUITE_LABELS
from lerobot_predvla.sweep.spec import Sweep, SweepError
from lerobot_predvla.utils.statistics import percent

RESULTS = "libero_four_suites"
SWEEP = "configs/sweeps/libero_four_suites.yaml"
PAPER_SWEEP = "configs/sweeps/paper.yaml"
COLUMNS = (*SHORT_SUITES, "libero_10")  # the paper's order (Table 3)
# The paper's published rows, by the configuration of PAPER_SWEEP whose `paper` field holds them.
PAPER_ROWS = (("paper: PredVLA, error regression (Table 3, 14 seeds)", "predvla"),
              ("paper: BC-Transformer (Table 4)", "B1"), ("paper: BC-RNN (Table 4)", "B2"))
# This project's rows: the configurations of SWEEP, in this order (a configuration the report lacks is left out).
OUR_CONFIGS = ("olt", "olt_open_loop", "olt_carried", "B1", "B2")


def _means(values: dict[str, float]) -> list[str]:
    """The 3-suite and 4-suite means of per-suite values (`summary.suites_mean`, as the report's); `—` unless every
    suite they average has one."""
    return [fmt_num(suites_mean([{"mean": values.get(s)} for s in suites])) for suites in (SHORT_SUITES, SUITES)]


def _published_row(label: str, values: dict[str, tuple[float, float]]) -> list[str]:
    return [label, *[fmt_mean_std(*values[s]) if s in values else MISSING for s in COLUMNS],
            *_means({s: v[0] for s, v in values.items()})]


def paper_rows(root: Path) -> list[list[str]]:
    """The paper's rows: Table 3's PredVLA and Table 4's baselines from PAPER_SWEEP, Table 6's exact open loop."""
    try:
        sweep = Sweep.load(Path(root) / PAPER_SWEEP)
    except SweepError as err:
        raise ReportError(str(err)) from err
    rows = []
    for label, config in PAPER_ROWS:
        if config not in sweep.configs:
            raise ReportError(f"{Path(root) / PAPER_SWEEP}: no configuration {config!r}, whose `paper` field holds "
                              f"the four-suite headline's row {label!r}.")
        rows.append(_published_row(label, {s: tuple(v) for s, v in sweep.configs[config].paper.items()}))
    rows.insert(1, _published_row("paper: PredVLA, exact open loop (Table 6, A6, 7 seeds)", PAPER_OPEN_LOOP))
    return rows


def blind_row(blind: dict) -> list[str]:
    """One demonstration replayed blind per suite (the state-0 plan on the other official init states)."""
    totals = {s: blind_replay.totals(blind[s]) for s in COLUMNS if blind.get(s)}
    return ["reference, not a policy: one demonstration replayed blind",
            *[fmt_rate(*totals[s]) if s in totals else MISSING for s in COLUMNS],
            *_means({s: percent(*t) for s, t in totals.items()})]


def our_rows(summary: dict) -> list[list[str]]:
    """The sweep's rows: mean ± std over training seeds per suite, the report's 3- and 4-suite means."""
    rows = []
    for name in OUR_CONFIGS:
        entry = summary.get("configs", {}).get(name)
        if entry is None:
            continue
        cells = entry.get("suites", {})
        try:
            rows.append([f"this project: {entry.get('label') or name}",
                         *[fmt_cell(cells[s]) if s in cells else MISSING for s in COLUMNS],
                         fmt_num(entry.get("mean3")), fmt_num(entry.get("mean4"))])
        except KeyError as err:
            raise ReportError(f"{RESULTS}/{SUMMARY_FILE}: configuration {name!r}: a suite cell without {err}.") from err
    return rows


def four_suite_table(root: Path, prefix: str, blind: dict | None) -> str | None:
    """The table and its caption, None while `results/libero_four_suites/report.json` does not exist. `prefix`: the
    path from the document to the repository root ("" for README.md, "../" for docs/)."""
    results_dir = Path(root) / "results" / RESULTS
    if not (results_dir / SUMMARY_FILE).is_file():
        return None
    body = paper_rows(root)
    if blind:
        body.append(blind_row(blind))
    body += our_rows(load_summary(results_dir))
    header = ["LIBERO success (%), mean ± std over training seeds", *[SUITE_LABELS[s] for s in COLUMNS],
              "3-suite mean", "4-suite mean"]
    return (f"All four suites ([sweep file]({prefix}{SWEEP}): scripted demonstrations, one front end fitted on the "
            f"four suites' demonstrations; [report]({prefix}results/{RESULTS}/report.md)); the 3-suite mean averages "
            "spatial, goal and object:\n\n" + table(header, body))
