"""One set of figures: a figure that two user pages (README.md, docs/*.md outside docs/research/) give for the same
key must be the same figure.

Keys are the names a figure is measured under: bench keys written beside their value (`1.25x
(`er_fast_over_floor_b1`)`, or a table row whose first cell names the keys of the values in the second, e.g.
`| `er_ms_fast_b1` / `er_ms_floor_b1` | 82.8 / 66.3 ms |`) and the cells of the generated headline table (row and
column). Two mentions agree when they are equal at the coarser one's precision (80 ms and 80.1 ms agree).
"""

import re
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NUMBER = r"(?<![\w.])(\d[\d,]*(?:\.\d+)?(?:e-?\d+)?)"
KEY = r"[a-z][a-z0-9_]*"
INLINE = re.compile(NUMBER + r"\s*(?:x|ms|s|Hz|GB|%|frames/s)?\s*\(`(" + KEY + r")`\)")
KEY_CELL = re.compile(rf"(`{KEY}`(?: / `{KEY}`)*)(?: \(.*\))?")
LINK = re.compile(r"\[([^\]]*)\]\([^)]*\)")
HEADLINE = re.compile(r"<!-- headline:start.*?-->(.*?)<!-- headline:end -->", re.S)


def user_pages(root: Path = REPO) -> dict[str, str]:
    paths = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    return {p.relative_to(root).as_posix(): p.read_text() for p in paths}


def parse(number: str) -> tuple[float, int]:
    """The value and its decimals (its precision)."""
    text = number.replace(",", "")
    return float(text), len(text.split(".")[1]) if "." in text and "e" not in text else 0


def cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("|") else []


def figures(text: str) -> list[tuple[str, tuple[float, int]]]:
    """(key, (value, decimals)) of every named figure of a page."""
    found = [(m.group(2), parse(m.group(1))) for m in INLINE.finditer(text)]
    for line in text.splitlines():
        row = cells(line)
        keys = KEY_CELL.fullmatch(row[0]) if len(row) >= 2 else None
        if keys:
            names = re.findall(rf"`({KEY})`", keys.group(1))
            values = re.match(r"\s*" + r"\s*/\s*".join([NUMBER] * len(names)), row[1])
            if values:
                found += [(name, parse(v)) for name, v in zip(names, values.groups(), strict=True)]
    for block in HEADLINE.findall(text):
        table = block.strip().split("\n\n")[0]  # the headline table; the per-seed table follows on results.md
        rows = [cells(line) for line in table.splitlines() if line.startswith("|") and not line.startswith("|---")]
        for row in rows[1:]:
            for column, cell in zip(rows[0][1:], row[1:], strict=False):
                value = re.match(NUMBER, cell)
                if value:
                    # The row's label without its number: the README numbers its own rows (a selection).
                    label = re.sub(r"^\d+\. ", "", LINK.sub(r"\1", row[0]))
                    found.append((f"headline: {label} / {column}", parse(value.group(1))))
    return found


def agree(a: tuple[float, int], b: tuple[float, int]) -> bool:
    decimals = min(a[1], b[1])
    return round(a[0], decimals) == round(b[0], decimals)


def disagreements(pages: dict[str, str]) -> dict[str, dict[str, list[float]]]:
    """Keys whose figures differ, with each page's values."""
    by_key: dict[str, dict[str, list[tuple[float, int]]]] = defaultdict(lambda: defaultdict(list))
    for page, text in pages.items():
        for key, value in figures(text):
            by_key[key][page].append(value)
    found = {}
    for key, per_page in by_key.items():
        values = [v for vs in per_page.values() for v in vs]
        if any(not agree(a, b) for a in values for b in values):
            found[key] = {page: [v for v, _ in vs] for page, vs in per_page.items()}
    return found


def test_user_pages_agree_on_every_named_figure():
    pages = user_pages()
    assert disagreements(pages) == {}
    keys = defaultdict(set)
    for page, text in pages.items():
        for key, _ in figures(text):
            keys[key].add(page)
    # not vacuous: bench keys and headline cells that several pages give
    assert {"README.md", "docs/results.md", "docs/speed.md"} <= keys["er_fast_over_floor_b1"]
    assert {"README.md", "docs/results.md", "docs/robot.md", "docs/speed.md"} <= keys["control_step_ms_p50"]
    assert sum(1 for key, where in keys.items() if key.startswith("headline:") and len(where) >= 2) >= 20


def test_a_figure_two_pages_give_differently_is_found():
    pages = user_pages()
    injected = dict(pages)
    injected["docs/results.md"] = pages["docs/results.md"].replace("1.25x (`er_fast_over_floor_b1`)",
                                                                   "1.4x (`er_fast_over_floor_b1`)")
    assert injected["docs/results.md"] != pages["docs/results.md"]
    found = disagreements(injected)
    assert list(found) == ["er_fast_over_floor_b1"]
    assert found["er_fast_over_floor_b1"]["docs/results.md"] == [1.4]
    assert found["er_fast_over_floor_b1"]["README.md"] == [1.25]

    cell = "| 77.4 (n = 1) | 87.8 (n = 1) |"
    assert cell in pages["README.md"]
    injected = {**pages, "README.md": pages["README.md"].replace(cell, "| 70.0 (n = 1) | 87.8 (n = 1) |")}
    found = disagreements(injected)
    assert len(found) == 1
    key, values = found.popitem()
    # the row's number moves as rows are added above it (and the README numbers its own); its label and column do not
    assert key.startswith("headline: fit_sensory_olt; 50 scripted demonstrations per task")
    assert key.endswith(" / PredVLA, error regression")
    assert values == {"README.md": [70.0], "docs/results.md": [77.4]}
