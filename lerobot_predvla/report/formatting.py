"""Markdown tables and the number formats of every generated table: the experiment reports (`predvla report`) and
the headline of README.md and docs/results.md (`predvla report --docs`)."""

from lerobot_predvla.utils.statistics import percent

MISSING = "—"  # a missing result


def table(header: list[str], rows: list[list[str]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


def fmt_mean_std(
    mean: float, std: float | None = None, n: int | None = None, digits: int = 2, count: bool = False
) -> str:
    """`mean ± std`, with ` (n = k)` when `count`. One seed has no spread to show: `72.00 (n = 1)`, never `± 0.00`;
    without `std` (a published mean alone) the mean only."""
    if n == 1:
        return f"{mean:.{digits}f} (n = 1)"
    text = f"{mean:.{digits}f}" + (f" ± {std:.{digits}f}" if std is not None else "")
    return text + (f" (n = {n})" if count and n is not None else "")


def fmt_num(value: float | None, signed: bool = False) -> str:
    if value is None:
        return MISSING
    return f"{value:+.2f}" if signed else f"{value:.2f}"


def fmt_params(value: int | None) -> str:
    return f"{value:,}" if value is not None else MISSING


def fmt_rate(successes: int, episodes: int) -> str:
    """`76.0 (152/200)`: the success rate and its counts."""
    return f"{percent(successes, episodes):.1f} ({successes}/{episodes})" if episodes else MISSING


def row_numbers(numbers: list[int], rows: int) -> str:
    """`all` of `rows` rows, or the numbers as `number_ranges` writes them."""
    return "all" if len(numbers) == rows else number_ranges(numbers)


def number_ranges(numbers: list[int]) -> str:
    """Ascending numbers, three or more in a row as a range: `1, 5`, `2-6`."""
    runs: list[list[int]] = []
    for number in numbers:
        if runs and number == runs[-1][-1] + 1:
            runs[-1].append(number)
        else:
            runs.append([number])
    return ", ".join(f"{run[0]}-{run[-1]}" if len(run) > 2 else ", ".join(map(str, run)) for run in runs)
