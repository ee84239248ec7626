"""The report's robustness section: success under shifted objects and on LIBERO-PRO / LIBERO-plus variants.

Its records are the runs of configurations with `object_shift` or `variant` (sweep/spec.py). One row per label
and suite (configurations that evaluate one policy in one mode under different conditions share a label), one column
per condition: each shift distance (unshifted `{cm: 0}` first), then each variant. A cell pools its runs' seeds:
success in % with successes/episodes, the episodes whose shifted bodies did not settle where they were put, and the
same success without those (settled episodes only: the record names them, `eval_info.json` gives their successes;
"n/a" for a record that kept only their count). A second table pairs every such configuration with `compare_to`
episode by episode with the run it names, per condition, over all pairs and over the settled ones.
The figure draws success against the shift distance, one line per row. With blind replays (`predvla report
--blind-replay DIR`, reports of `predvla blind-replay`, each at one object shift), one plan replayed blind is a
reference row of the table and a dashed line of the figure.
"""

from pathlib import Path

from lerobot_predvla.report.formatting import MISSING, fmt_rate, table
from lerobot_predvla.report.results import ReportError, run_episodes, unsettled_keys
from lerobot_predvla.sims.libero import blind_replay
from lerobot_predvla.sims.libero.protocol import SUITE_LABELS
from lerobot_predvla.utils.io import atomic_save_figure
from lerobot_predvla.utils.statistics import episode_totals, percent

ROBUSTNESS_FIGURE = "success_vs_shift.png"
BLIND_LABEL = "reference, not a policy: one plan replayed blind"
BlindLine = dict[str, list[tuple[float, int, int]]]  # suite -> (object shift in cm, successes, episodes) per report


def condition(record: dict) -> tuple[str, float, str] | None:
    """(variant or "", object shift in cm, column title) of a run, or None for a run of neither kind."""
    shift, variant = record.get("object_shift"), record.get("variant")
    if shift is None and variant is None:
        return None
    cm = float(shift["cm"]) if shift else 0.0
    parts = [variant] if variant else []
    if shift:
        target = f", target {float(shift['target_cm']):g} cm" if shift.get("target_cm") else ""
        parts.append(f"{cm:g} cm{target}")
    return variant or "", cm, " + ".join(parts)


def _settled(record: dict, runs_dir: Path | None) -> tuple[int, int] | None:
    """(successes, episodes) of a run over its episodes whose shifted object settled where it was put: its record
    names the unsettled ones, its `eval_info.json` files give each episode's success; None when either is missing."""
    unsettled = unsettled_keys(record)
    if unsettled is None:
        return None
    if not unsettled:
        return episode_totals(record["tasks"].values())
    episodes = run_episodes(runs_dir, record["config"], record["suite"], int(record["seed"])) if runs_dir else {}
    if not unsettled <= episodes.keys():
        return None
    kept = [ok for key, ok in episodes.items() if key not in unsettled]
    return sum(kept), len(kept)


def _cells(records: list[dict], runs_dir: Path | None = None) -> dict[tuple[str, str], dict[tuple, list]]:
    """{(label, suite): {condition: [successes, episodes, unsettled, settled successes, settled episodes]}}, pooled
    over seeds; the settled counts are None when a run does not tell them (`_settled`)."""
    cells: dict = {}
    for r in records:
        key = condition(r)
        if key is None:
            continue
        successes, episodes = episode_totals(r["tasks"].values())
        settled = _settled(r, runs_dir)
        cell = cells.setdefault((r.get("label") or r["config"], r["suite"]), {}).setdefault(key, [0, 0, 0, 0, 0])
        cell[0] += successes
        cell[1] += episodes
        cell[2] += r.get("shift_unsettled") or 0
        cell[3:] = [None, None] if settled is None or cell[3] is None else [cell[3] + settled[0], cell[4] + settled[1]]
    return cells


def blind_line(folders: list[Path]) -> BlindLine:
    """The blind replays' points per suite, by shift, from `predvla blind-replay` report folders."""
    line: BlindLine = {}
    for folder in folders:
        try:
            found = blind_replay.shift_totals(Path(folder))
        except ValueError as err:
            raise ReportError(f"--blind-replay {folder}: {err}") from err
        for suite, point in found.items():
            line.setdefault(suite, []).append(point)
    return {suite: sorted(points) for suite, points in line.items()}


def _with_blind(cells: dict, blind: BlindLine | None) -> dict:
    """`cells` with the blind replays' row per suite (every episode settled: the replays report their shifts apart)."""
    for suite, points in (blind or {}).items():
        row = cells.setdefault((BLIND_LABEL, suite), {})
        for cm, successes, episodes in points:
            cell = row.setdefault(("", cm, f"{cm:g} cm"), [0, 0, 0, 0, 0])
            cell[:] = [cell[0] + successes, cell[1] + episodes, 0, cell[3] + successes, cell[4] + episodes]
    return cells


def _fmt(cell: list | None) -> str:
    if cell is None:
        return MISSING
    successes, episodes, unsettled, settled_successes, settled_episodes = cell
    text = fmt_rate(successes, episodes) + (f", {unsettled} unsettled" if unsettled else "")
    if settled_episodes is None:
        return text + "; settled n/a"
    return text + (f"; settled {fmt_rate(settled_successes, settled_episodes)}" if unsettled else "")


def robustness_table(records: list[dict], runs_dir: Path | None = None, blind: BlindLine | None = None) -> str | None:
    """The Markdown table (see the module docstring), or None without such runs."""
    cells = _with_blind(_cells(records, runs_dir), blind)
    if not cells:
        return None
    columns = sorted({key for row in cells.values() for key in row})  # shifts (no variant) first, by distance
    rows = [[label, SUITE_LABELS.get(suite, suite), *[_fmt(row.get(key)) for key in columns]]
            for (label, suite), row in cells.items()]
    return table(["Policy", "Suite", *[title for _, _, title in columns]], rows)


def _quadrants(pairs: dict | None) -> list[str]:
    """Episode pairs, both succeed / only the policy / only the one it is compared with / neither, sign test p."""
    if pairs is None:
        return ["n/a"] * 3
    both, neither = pairs["successes"] - pairs["only"], pairs["pairs"] - pairs["successes"] - pairs["only_against"]
    return [str(pairs["pairs"]), f"{both} / {pairs['only']} / {pairs['only_against']} / {neither}",
            f"{pairs['sign_test_p']:.3g}"]


def robustness_pairs_table(records: list[dict], summary: dict) -> str | None:
    """Every configuration of the robustness table with `compare_to`, paired episode by episode with it
    (`paired.paired_episodes`) per condition and suite, over all pairs and over the pairs whose shifted object settled
    in both runs (a variant shifts nothing: all its pairs); rows by condition, then by configuration name; None without
    such pairs."""
    conditions = {r["config"]: key for r in records if (key := condition(r)) is not None}
    rows = []
    for name in sorted(conditions.keys() & summary["configs"].keys(), key=lambda n: (conditions[n], n)):
        entry = summary["configs"][name]
        for suite, pairs in entry.get("episodes", {}).items():
            against = summary["configs"].get(pairs["against"], {}).get("label") or pairs["against"]
            rows.append([entry.get("label") or name, against, SUITE_LABELS.get(suite, suite), conditions[name][2],
                         *_quadrants(pairs), *_quadrants(pairs.get("settled", pairs))])
    if not rows:
        return None
    return table(["Policy", "against", "Suite", "condition", "pairs", "both / only policy / only against / neither",
                  "sign test p", "settled: pairs", "settled: both / only policy / only against / neither",
                  "settled: sign test p"], rows)


def robustness_figure(records: list[dict], path: Path, blind: BlindLine | None = None) -> bool:
    """Success against the object's shift, one line per row (a marker for a row at one distance; the blind replay
    dashed); False when no row has a shift."""
    lines = {}
    for row, by_condition in _with_blind(_cells(records), blind).items():
        points = sorted((cm, percent(c[0], c[1])) for (variant, cm, _), c in by_condition.items()
                        if not variant and c[1])
        if points:
            lines[row] = points
    if not lines:
        return False
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for (label, suite), points in lines.items():
        name = label if len({s for _, s in lines}) == 1 else f"{label} ({SUITE_LABELS.get(suite, suite)})"
        style = {"color": "black", "linestyle": "--"} if label == BLIND_LABEL else {}
        ax.plot(*zip(*points, strict=True), marker="o", label=name, **style)
    ax.set_xlabel("object shifted (cm)")
    ax.set_ylabel("success (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16))  # below: the lines fill the axes
    atomic_save_figure(fig, path, dpi=130, bbox_inches="tight")
    plt.close(fig)
    return True
