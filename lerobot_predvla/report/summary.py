"""The statistics of a report (its `report.json`): per configuration and suite, the mean and sample standard
deviation of the success rate across seeds; 3-suite (spatial, goal, object) and 4-suite means of the suite means,
which need every suite; paired differences over the seeds two configurations both have; one cell over the union
of the seeds of the configurations that pool (`pool_with`); and the configurations whose paired comparisons pool over
evaluation sets (`pool_sets`, their episodes counted by `paired.paired_episodes`)."""

import numpy as np

from lerobot_predvla.columns import SUITES
from lerobot_predvla.report.results import ReportError, Results
from lerobot_predvla.sims.libero.protocol import SHORT_SUITES
from lerobot_predvla.utils.statistics import mean_std


def seed_cell(seeds: dict[int, float], planned: list[int]) -> dict:
    """A table cell: mean and sample std over the seeds' success rates, with the planned seeds it lacks."""
    mean, std = mean_std(list(seeds.values()))
    return {
        "mean": mean,
        "std": std,
        "n": len(seeds),
        "planned": len(planned),
        "seeds": {str(k): v for k, v in sorted(seeds.items())},
        "missing_seeds": sorted(set(planned) - set(seeds)),
    }


def suites_mean(cells: list[dict]) -> float | None:
    """The mean of the cells' means; None unless every cell has one."""
    means = [c["mean"] for c in cells]
    return float(np.mean(means)) if all(m is not None for m in means) else None


def cell(results: Results, config: str, suite: str) -> dict:
    return seed_cell(results.rates.get(config, {}).get(suite, {}), results.planned.get(config, {}).get(suite, []))


def config_mean(results: Results, config: str, suites: tuple[str, ...]) -> float | None:
    return suites_mean([cell(results, config, s) for s in suites])


def pooled_cell(results: Results, configs: list[str], suite: str) -> dict:
    """One cell over the union of the configurations' seeds (each seed in one configuration only)."""
    rates: dict[int, float] = {}
    planned: set[int] = set()
    for name in configs:
        own = results.rates.get(name, {}).get(suite, {})
        twice = sorted(set(own) & set(rates))
        if twice:
            raise ReportError(
                f"configurations {configs} pool their seeds (pool_with), but seeds {twice} of "
                f"{suite} were run by more than one of them."
            )
        rates.update(own)
        planned |= set(results.planned.get(name, {}).get(suite, []))
    return seed_cell(rates, sorted(planned))


def paired_seeds(results: Results, config: str, reference: str, suite: str) -> dict:
    """Mean and std over matched seeds of (config - reference)."""
    a, b = results.rates.get(config, {}).get(suite, {}), results.rates.get(reference, {}).get(suite, {})
    seeds = sorted(set(a) & set(b))
    mean, std = mean_std([a[s] - b[s] for s in seeds])
    return {"delta": mean, "std": std, "n": len(seeds), "seeds": seeds}


def summarize(results: Results) -> dict:
    """The aggregates of `report.json`, but for the paired episodes (`paired.paired_episodes`) and figures."""
    previous = results.ladder_previous()
    reference = results.reference()
    suites = results.suites()
    out = {"protocol": results.protocol, "suites": suites, "reference": reference, "configs": {}}
    for name, c in results.configs.items():
        entry = {
            **{k: c.get(k) for k in ("group", "label", "compare_to", "pool_with", "branch", "corruption")},
            "paper": c.get("paper") or {},
            "params": results.params.get(name),
            "suites": {s: cell(results, name, s) for s in suites},
            "mean3": config_mean(results, name, SHORT_SUITES),
            "mean4": config_mean(results, name, SUITES),
        }
        against = (
            previous.get(name)
            if c.get("group") == "ladder"
            else (c.get("compare_to") or (reference if c.get("group") in ("ablation", "corruption") else None))
        )
        if against and against != name:
            entry["paired_against"] = against
            entry["paired"] = {s: paired_seeds(results, name, against, s) for s in suites}
            m, p = entry["mean3"], config_mean(results, against, SHORT_SUITES)
            entry["delta_mean3"] = m - p if m is not None and p is not None else None
        out["configs"][name] = entry
    out["pooled"] = {}
    for target, names in results.pools().items():
        cells = {s: pooled_cell(results, names, s) for s in suites}
        out["pooled"][target] = {
            "configs": names,
            "suites": cells,
            "mean3": suites_mean([cells.get(s, {"mean": None}) for s in SHORT_SUITES]),
            "mean4": suites_mean([cells.get(s, {"mean": None}) for s in SUITES]),
        }
    set_pools = results.set_pools()
    if set_pools:  # (a report without them keeps the keys it had)
        out["pooled_sets"] = {target: {"configs": names} for target, names in set_pools.items()}
    return out
