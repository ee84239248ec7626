"""The report's robustness section: success under shifted objects and on LIBERO-PRO / LIBERO-plus variants.

Its records are the runs of configurations with `object_shift` or `variant` (sweep/spec.py). One row per label
and suite (configurations that evaluate one policy in one mode under different conditions share a label), one column
per condition: each shift distance (unshifted `{cm: 0}` first), then each variant. A cell pools its runs' seeds:
success in % with successes/episodes, and the episodes whose shifted bodies did not settle where they were put.
The figure draws success against the shift distance, one line per row.
"""

from pathlib import Path

from lerobot_predvla.report.formatting import MISSING, table
from lerobot_predvla.sims.libero.protocol import SUITE_LABELS
from lerobot_predvla.utils.io import atomic_save_figure
from lerobot_predvla.utils.statistics import episode_totals, percent

ROBUSTNESS_FIGURE = "success_vs_shift.png"


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


def _cells(records: list[dict]) -> dict[tuple[str, str], dict[tuple[str, float, str], list[int]]]:
    """{(label, suite): {condition: [successes, episodes, unsettled]}}, pooled over seeds."""
    cells: dict = {}
    for r in records:
        key = condition(r)
        if key is None:
            continue
        successes, episodes = episode_totals(r["tasks"].values())
        cell = cells.setdefault((r.get("label") or r["config"], r["suite"]), {}).setdefault(key, [0, 0, 0])
        cell[0] += successes
        cell[1] += episodes
        cell[2] += r.get("shift_unsettled") or 0
    return cells


def _fmt(cell: list[int] | None) -> str:
    if cell is None:
        return MISSING
    successes, episodes, unsettled = cell
    text = f"{percent(successes, episodes):.1f} ({successes}/{episodes})"
    return text + (f", {unsettled} unsettled" if unsettled else "")


def robustness_table(records: list[dict]) -> str | None:
    """The Markdown table (see the module docstring), or None without such runs."""
    cells = _cells(records)
    if not cells:
        return None
    columns = sorted({key for row in cells.values() for key in row})  # shifts (no variant) first, by distance
    rows = [[label, SUITE_LABELS.get(suite, suite), *[_fmt(row.get(key)) for key in columns]]
            for (label, suite), row in cells.items()]
    return table(["Policy", "Suite", *[title for _, _, title in columns]], rows)


def robustness_figure(records: list[dict], path: Path) -> bool:
    """Success against the object's shift, one line per row with two or more shift distances; False when none."""
    lines = {}
    for row, by_condition in _cells(records).items():
        points = sorted((cm, percent(c[0], c[1])) for (variant, cm, _), c in by_condition.items()
                        if not variant and c[1])
        if len(points) >= 2:
            lines[row] = points
    if not lines:
        return False
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for (label, suite), points in lines.items():
        name = label if len({s for _, s in lines}) == 1 else f"{label} ({SUITE_LABELS.get(suite, suite)})"
        ax.plot(*zip(*points, strict=True), marker="o", label=name)
    ax.set_xlabel("object shifted (cm)")
    ax.set_ylabel("success (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    atomic_save_figure(fig, path, dpi=130, bbox_inches="tight")
    plt.close(fig)
    return True
