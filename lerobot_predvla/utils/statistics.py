"""Success arithmetic, in one place for the run records, reports, headline, blind replay and demos: success rates in %
from success and episode counts, their totals over tasks, the mean and sample standard deviation over training seeds,
and the exact sign test on paired episodes."""

from collections.abc import Iterable

import numpy as np
from scipy.stats import binomtest


def percent(successes: int, episodes: int) -> float:
    """Successes out of episodes, in %."""
    return 100.0 * successes / episodes


def episode_totals(tasks: Iterable[dict]) -> tuple[int, int]:
    """(successes, episodes) summed over tasks' `{"successes": s, "episodes": n}` counts."""
    tasks = list(tasks)
    return sum(t["successes"] for t in tasks), sum(t["episodes"] for t in tasks)


def success_rate(tasks: dict[str, dict]) -> float:
    """The success rate (%) over all episodes of a run's tasks (`{task: {"successes": s, "episodes": n}}`)."""
    return percent(*episode_totals(tasks.values()))


def task_rates(tasks: dict[str, dict]) -> dict[str, float]:
    """The success rate (%) of each task."""
    return {task: percent(t["successes"], t["episodes"]) for task, t in tasks.items()}


def mean_std(values: list[float]) -> tuple[float | None, float | None]:
    """Mean and sample standard deviation (0 for one value; None, None for none)."""
    if not values:
        return None, None
    arr = np.asarray(values, dtype=float)
    return float(arr.mean()), float(arr.std(ddof=1)) if len(arr) > 1 else 0.0


def sign_test(only_a: int, only_b: int) -> float:
    """Exact two-sided sign test (binomial, p = 1/2) on the pairs that succeed in only one of the two runs."""
    n = only_a + only_b
    return 1.0 if n == 0 else float(binomtest(only_a, n, 0.5).pvalue)
