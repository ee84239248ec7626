"""Paired episodes: a configuration with `compare_to` (e.g. exact open loop against error regression) is compared
episode by episode, from the runs' `eval_info.json` files. Both runs of a seed start from the same init states when
they share the evaluation seed, reset mode and protocol, so each episode is a pair; the report counts the pairs that
succeed in only one of the two and gives the exact two-sided sign test on them. Two runs that load one checkpoint
path pair only when they evaluated the same weights (`same_model`). A pool, of further seeds (`pool_with`) or of
other evaluation sets (`pool_sets`), gets one sign test over all its configurations' pairs. Where an object was
shifted, the pairs are counted once more without the episodes whose shifted object did not settle in either run."""

from collections.abc import Iterable
from pathlib import Path

from lerobot_predvla.report.results import run_episodes, unsettled_keys
from lerobot_predvla.utils.statistics import percent, sign_test

PAIRING_KEYS = ("eval_seed", "init_states", "episode_length")


def same_starts(a: dict, b: dict) -> bool:
    """Whether episode i of a task starts from the same state in both runs. From the official init states episode
    i starts from init state i whatever the number of episodes; randomised resets also need the same number."""
    return all(a.get(k) == b.get(k) for k in PAIRING_KEYS) and (
        a.get("init_states") is not False or a.get("n_episodes_per_task") == b.get("n_episodes_per_task")
    )


def same_model(a: dict, b: dict) -> bool:
    """Whether two runs that load one checkpoint path evaluated the same weights: a training redone in place (its
    checkpoint lost) writes new weights under the old path. Runs of different checkpoints (a baseline against
    PredVLA) compare different models on purpose; records written before `model_sha256` existed pair only with
    each other."""
    return a.get("checkpoint") != b.get("checkpoint") or a.get("model_sha256") == b.get("model_sha256")


PAIR_COUNTS = ("pairs", "successes", "against_successes", "only", "only_against")  # of a set of episode pairs


def sum_counts(parts: Iterable[dict[str, int]]) -> dict[str, int]:
    """PAIR_COUNTS summed over several sets of episode pairs (tasks, or the configurations of a pool)."""
    parts = list(parts)  # read once per count
    return {count: sum(part[count] for part in parts) for count in PAIR_COUNTS}


def add_pairs(tasks: dict[str, dict[str, int]], mine: dict, theirs: dict, keys: Iterable[tuple[str, int]]) -> None:
    """Count the episode pairs `keys` of two runs (`run_episodes`) into `tasks` (task -> PAIR_COUNTS)."""
    for key in keys:
        a, b = mine[key], theirs[key]
        task = tasks.setdefault(key[0], dict.fromkeys(PAIR_COUNTS, 0))
        for count, value in zip(PAIR_COUNTS, (1, a, b, a and not b, b and not a), strict=True):
            task[count] += value


def with_sign_test(counts: dict[str, int]) -> dict:
    """PAIR_COUNTS and the exact two-sided sign test on the pairs that succeed in only one of the two runs."""
    return {**counts, "sign_test_p": sign_test(counts["only"], counts["only_against"])}


def paired_episodes(summary: dict, records: list[dict], runs_dir: Path) -> None:
    """Add `episodes` (per suite: pairs, successes, discordant counts, sign test) to every `compare_to` entry; where
    an object was shifted, `settled`: the same over the pairs whose shifted objects settled in both runs (None when a
    record does not tell which did). Then the pools: `pool_with` (further seeds) and `pool_sets` (other evaluation
    sets), one sign test over all their configurations' pairs."""
    by_run = {(r["config"], r["suite"], int(r["seed"])): r for r in records}
    for name, entry in summary["configs"].items():
        against = entry.get("compare_to")
        if not against:
            continue
        for suite in summary["suites"]:
            comparable = sorted(
                seed
                for (c, s, seed), r in by_run.items()
                if c == name
                and s == suite
                and (against, suite, seed) in by_run
                and same_starts(r, by_run[(against, suite, seed)])
            )
            seeds = [
                seed for seed in comparable if same_model(by_run[(name, suite, seed)], by_run[(against, suite, seed)])
            ]
            summary.setdefault("unpaired", []).extend(
                {"config": name, "against": against, "suite": suite, "seed": seed}
                for seed in comparable
                if seed not in seeds
            )
            tasks: dict[str, dict[str, int]] = {}  # task -> PAIR_COUNTS over its paired episodes
            settled: dict[str, dict[str, int]] | None = {}  # the same over the pairs that settled in both runs
            shifted = False
            for seed in seeds:
                runs = by_run[(name, suite, seed)], by_run[(against, suite, seed)]
                mine, theirs = (run_episodes(runs_dir, c, suite, seed) for c in (name, against))
                keys = mine.keys() & theirs.keys()
                add_pairs(tasks, mine, theirs, keys)
                shifted = shifted or any(r.get("object_shift") for r in runs)
                unsettled = [unsettled_keys(r) for r in runs]
                if settled is not None and None not in unsettled:
                    add_pairs(settled, mine, theirs, keys - set.union(*unsettled))
                else:
                    settled = None
            if tasks:
                paired = entry.setdefault("episodes", {})[suite] = {
                    "against": against,
                    "seeds": seeds,
                    **with_sign_test(sum_counts(tasks.values())),
                    "tasks": dict(sorted(tasks.items(), key=lambda item: int(item[0]))),
                }
                if shifted:
                    paired["settled"] = None if settled is None else with_sign_test(sum_counts(settled.values()))
    for pool in [*summary.get("pooled", {}).values(), *summary.get("pooled_sets", {}).values()]:
        for suite in summary["suites"]:
            parts = [e for name in pool["configs"] if (e := summary["configs"][name].get("episodes", {}).get(suite))]
            if len(parts) < 2:  # one configuration's pairs are already in the table as they are
                continue
            pool.setdefault("episodes", {})[suite] = {
                "against": " + ".join(e["against"] for e in parts),
                "seeds": sorted({seed for e in parts for seed in e["seeds"]}),
                **with_sign_test(sum_counts(parts)),
            }


def pairs_apart(summary: dict, tasks_apart: list[int]) -> None:
    """Add `apart` to every paired entry of `paired_episodes` and of its pools (per suite): the counts and sign test
    over the tasks `tasks_apart` (`tasks`) and over the other tasks (`other`), each where it has pairs;
    `summary["tasks_apart"]` names them. For tasks a setting was chosen on (a screen's), reported apart from those
    it was not (the protocols' rule)."""
    named = {str(t) for t in tasks_apart}
    summary["tasks_apart"] = sorted({int(t) for t in tasks_apart})
    groups = (("tasks", True), ("other", False))
    for entry in summary["configs"].values():
        for paired in entry.get("episodes", {}).values():
            parts = {g: [c for task, c in paired["tasks"].items() if (task in named) == inside] for g, inside in groups}
            paired["apart"] = {g: sum_counts(p) for g, p in parts.items() if p}
    for pool in [*summary.get("pooled", {}).values(), *summary.get("pooled_sets", {}).values()]:
        for suite, pooled in pool.get("episodes", {}).items():
            entries = [e for name in pool["configs"] if (e := summary["configs"][name].get("episodes", {}).get(suite))]
            pooled["apart"] = {g: sum_counts([e["apart"][g] for e in entries if g in e["apart"]]) for g, _ in groups
                               if any(g in e["apart"] for e in entries)}
    for _, episodes in paired_entries(summary):
        for paired in episodes.values():
            paired["apart"] = {g: with_sign_test(counts) for g, counts in paired["apart"].items()}


def paired_entries(summary: dict) -> list[tuple[str, dict]]:
    """(name, per-suite paired episodes) of every `compare_to` configuration, then of every pool over its seeds
    (`pool_with`) or evaluation sets (`pool_sets`, named "..., pooled over evaluation sets"): the rows of the
    paired-episode tables."""
    return [
        *((name, entry.get("episodes", {})) for name, entry in summary["configs"].items()),
        *((" + ".join(pool["configs"]), pool.get("episodes", {})) for pool in summary.get("pooled", {}).values()),
        *((f"{' + '.join(pool['configs'])}, pooled over evaluation sets", pool.get("episodes", {}))
          for pool in summary.get("pooled_sets", {}).values()),
    ]


def paired_task_rates(summary: dict, config: str, reference: str, suite: str) -> dict[str, tuple[float, float]] | None:
    """Per task, (reference's success, config's change) in % over the episodes both ran from the same starts
    (`paired_episodes`); None when the two have no paired episodes in the suite."""
    paired = summary["configs"].get(config, {}).get("episodes", {}).get(suite)
    if not paired or paired["against"] != reference:
        return None
    return {
        task: (
            percent(t["against_successes"], t["pairs"]),
            percent(t["successes"] - t["against_successes"], t["pairs"]),
        )
        for task, t in paired["tasks"].items()
    }
