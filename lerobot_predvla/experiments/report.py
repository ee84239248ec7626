"""Paper-format tables and figures from the run records of `predvla sweep`.

Inputs: `RUNS_DIR/records/**/*.json` (one per configuration, suite and seed) and, when present,
`RUNS_DIR/plan.json` (every planned run and each configuration's description), which lets the report mark runs
that are missing. Outputs in REPORT_DIR: `report.md` (Markdown tables and figures, readable on GitHub),
`report.json` (the aggregates, read by `predvla push --results`) and the PNG figures.

Success rates are percentages per (configuration, suite, seed): successes / episodes over all tasks. Tables
show mean +/- sample standard deviation across seeds; 3-suite (spatial, goal, object) and 4-suite means are
means of the suite means and need every suite. Paired differences use the seeds both configurations have.

A configuration with `compare_to` (e.g. exact open loop against error regression) is also compared episode by
episode, from the runs' `eval_info.json` files: both runs of a seed start from the same init states when they share
the evaluation seed, reset mode and protocol, so each episode is a pair. The report counts the pairs that succeed
in only one of the two and gives the exact two-sided sign test on them. Two runs that load one checkpoint path
pair only when they evaluated the same weights (`same_model`).

Configurations that name another in `pool_with` (further training seeds of the same model and evaluation) also
get one row over the union of their seeds, and their paired episodes one sign test over all the seeds' pairs.
"""

import json
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

from lerobot_predvla.columns import SUITES
from lerobot_predvla.experiments.eval_info import EVAL_INFO_FILE, EvalInfoError, episode_successes
from lerobot_predvla.experiments.logs import TrainingRun, training_runs
from lerobot_predvla.experiments.lr_selection import (
    CANDIDATE_PREFIX,
    LR_SWEEP_DIR,
    candidate_name,
    pending_selections,
)
from lerobot_predvla.experiments.sweep import TRAIN_DONE_FILE, eval_run_dir, run_log_path
from lerobot_predvla.policies.predvla.configuration_predvla import MODULE_NAMES
from lerobot_predvla.sims.libero.protocol import SHORT_SUITES, SUITE_LABELS
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text

SUMMARY_FILE = "report.json"
REPORT_FILE = "report.md"
FIGURES = {
    "ladder": "ladder.png",
    "params": "params_vs_success.png",
    "pertask": "ablation_pertask.png",
    "corruption": "corruption.png",
    "tasks": "success_per_task.png",
}
# Published LIBERO 4-suite means for context (trainable parameters, mean success %); not a controlled comparison.
PUBLISHED_REFERENCES = (
    ("OpenVLA", 7.0e9, 76.5),
    ("Octo", 93e6, 75.1),
    ("SmolVLA", 0.45e9, 87.3),
    ("pi0", 3.3e9, 94.15),
    ("PredVLA (paper)", 675_732, 75.35),
)
PARAMETERLESS_REFERENCES = (("Diffusion Policy", 72.4),)  # its parameter count is not given with the result
MISSING = "—"
NOT_RUN = "not run yet"  # a learning-rate candidate of a sweep still running
# beside the report: `python -m lerobot_predvla.sims.libero.start_spread --demos`
START_SPREAD_FILE = "start_spread.json"
INSPECT_DIR = "inspect"  # beside the report: inspect/seed<N>/ from `predvla inspect <train dir> --every N`
CURVES_FIGURE = "training_curves.png"


class ReportError(ValueError):
    """No usable records, or a malformed record or plan."""


def _load_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ReportError(f"{path}: unreadable JSON ({err}).") from err


def load_records(runs_dir: Path) -> list[dict]:
    records_dir = Path(runs_dir) / "records"
    paths = sorted(records_dir.rglob("*.json")) if records_dir.is_dir() else []
    if not paths:
        raise ReportError(f"{records_dir}: no run records (*.json); run `predvla sweep ... --runs-dir {runs_dir}`.")
    records = []
    for path in paths:
        record = _load_json(path)
        missing = [k for k in ("config", "suite", "seed", "tasks") if k not in record]
        if missing:
            raise ReportError(f"{path}: not a sweep run record (missing {missing}).")
        records.append(record)
    return records


def load_summary(path: Path) -> dict:
    """The `report.json` of a report directory (or the file itself)."""
    path = Path(path)
    path = path / SUMMARY_FILE if path.is_dir() else path
    if not path.is_file():
        raise ReportError(f"{path}: no {SUMMARY_FILE}; run `predvla report RUNS_DIR --out REPORT_DIR` first.")
    return _load_json(path)


def success_rate(record: dict) -> float:
    tasks = record["tasks"].values()
    return 100.0 * sum(t["successes"] for t in tasks) / sum(t["episodes"] for t in tasks)


def _mean_std(values: list[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    arr = np.asarray(values, dtype=float)
    return float(arr.mean()), float(arr.std(ddof=1)) if len(arr) > 1 else 0.0


def _cell(seeds: dict[int, float], planned: list[int]) -> dict:
    """A table cell: mean and sample std over the seeds' success rates, with the planned seeds it lacks."""
    mean, std = _mean_std(list(seeds.values()))
    return {"mean": mean, "std": std, "n": len(seeds), "planned": len(planned),
            "seeds": {str(k): v for k, v in sorted(seeds.items())}, "missing_seeds": sorted(set(planned) - set(seeds))}


def _suite_mean(cells: list[dict]) -> float | None:
    means = [c["mean"] for c in cells]
    return float(np.mean(means)) if all(m is not None for m in means) else None


@dataclass
class Results:
    """Per-seed success rates and per-task rates, indexed by configuration and suite."""

    rates: dict[str, dict[str, dict[int, float]]]  # config -> suite -> seed -> %
    tasks: dict[str, dict[str, dict[int, dict[str, float]]]]  # config -> suite -> seed -> task -> %
    planned: dict[str, dict[str, list[int]]]  # config -> suite -> seeds
    configs: dict[str, dict]  # config -> description (group, label, compare_to, branch, corruption, ...)
    params: dict[str, int | None]
    protocol: str

    @classmethod
    def build(cls, records: list[dict], plan: dict | None) -> "Results":
        rates: dict = {}
        tasks: dict = {}
        configs: dict = dict(plan["configs"]) if plan else {}
        params: dict = {}
        for r in records:
            rates.setdefault(r["config"], {}).setdefault(r["suite"], {})[int(r["seed"])] = success_rate(r)
            tasks.setdefault(r["config"], {}).setdefault(r["suite"], {})[int(r["seed"])] = {
                k: 100.0 * t["successes"] / t["episodes"] for k, t in r["tasks"].items()
            }
            configs.setdefault(r["config"], {k: r.get(k) for k in (
                "group", "label", "compare_to", "pool_with", "branch", "corruption", "eval_overrides")})
            if r.get("parameters") is not None:
                params[r["config"]] = int(r["parameters"])
        planned: dict = {}
        for run in plan["runs"] if plan else []:
            planned.setdefault(run["config"], {}).setdefault(run["suite"], []).append(int(run["seed"]))
        for name in configs:
            params.setdefault(name, None)
            if name not in planned:  # without a plan, what was run is what was planned
                planned[name] = {s: sorted(seeds) for s, seeds in rates.get(name, {}).items()}
        episodes = sorted({int(r["n_episodes_per_task"]) for r in records if "n_episodes_per_task" in r})
        caps = sorted({int(r["episode_length"]) for r in records if "episode_length" in r})
        protocol = (f"{'/'.join(map(str, episodes)) or '?'} rollouts per task, "
                    f"{'/'.join(map(str, caps)) or '?'}-step cap")
        return cls(rates, tasks, planned, configs, params, protocol)

    # ----- aggregates -------------------------------------------------------------------------------------
    def suites(self) -> list[str]:
        present = {s for by_suite in self.planned.values() for s in by_suite} | {
            s for by_suite in self.rates.values() for s in by_suite}
        return [s for s in (*SHORT_SUITES, "libero_10") if s in present]

    def cell(self, config: str, suite: str) -> dict:
        return _cell(self.rates.get(config, {}).get(suite, {}), self.planned.get(config, {}).get(suite, []))

    def suite_mean(self, config: str, suites: tuple[str, ...]) -> float | None:
        return _suite_mean([self.cell(config, s) for s in suites])

    def pools(self) -> dict[str, list[str]]:
        """Each configuration that others name in `pool_with`, with them: `{target: [target, *members]}`."""
        pools: dict[str, list[str]] = {}
        for name, c in self.configs.items():
            if c.get("pool_with") in self.configs:  # a target neither planned nor recorded has no row to join
                pools.setdefault(c["pool_with"], [c["pool_with"]]).append(name)
        return pools

    def pooled_cell(self, configs: list[str], suite: str) -> dict:
        """One cell over the union of the configurations' seeds (each seed in one configuration only)."""
        rates: dict[int, float] = {}
        planned: set[int] = set()
        for name in configs:
            own = self.rates.get(name, {}).get(suite, {})
            twice = sorted(set(own) & set(rates))
            if twice:
                raise ReportError(f"configurations {configs} pool their seeds (pool_with), but seeds {twice} of "
                                  f"{suite} were run by more than one of them.")
            rates.update(own)
            planned |= set(self.planned.get(name, {}).get(suite, []))
        return _cell(rates, sorted(planned))

    def paired(self, config: str, reference: str, suite: str) -> dict:
        """Mean and std over matched seeds of (config - reference)."""
        a, b = self.rates.get(config, {}).get(suite, {}), self.rates.get(reference, {}).get(suite, {})
        seeds = sorted(set(a) & set(b))
        mean, std = _mean_std([a[s] - b[s] for s in seeds])
        return {"delta": mean, "std": std, "n": len(seeds), "seeds": seeds}

    def of_group(self, group: str) -> list[str]:
        return [name for name, c in self.configs.items() if c.get("group") == group]

    def reference(self) -> str | None:
        """The intact model: `predvla` when present, else the first main configuration."""
        main = self.of_group("main")
        return "predvla" if "predvla" in self.configs else (main[0] if main else None)

    def ladder_previous(self) -> dict[str, str | None]:
        """Each rung's comparison rung: `compare_to`, else the preceding main-chain rung."""
        previous, last = {}, self.reference()  # the chain starts at the intact model (L0)
        for name in self.of_group("ladder"):
            c = self.configs[name]
            previous[name] = c.get("compare_to") or last
            if not c.get("branch"):
                last = name
        return previous

    def summary(self) -> dict:
        previous = self.ladder_previous()
        reference = self.reference()
        out = {"protocol": self.protocol, "suites": self.suites(), "reference": reference, "configs": {}}
        for name, c in self.configs.items():
            entry = {**{k: c.get(k) for k in ("group", "label", "compare_to", "pool_with", "branch", "corruption")},
                     "paper": c.get("paper") or {},
                     "params": self.params.get(name),
                     "suites": {s: self.cell(name, s) for s in self.suites()},
                     "mean3": self.suite_mean(name, SHORT_SUITES),
                     "mean4": self.suite_mean(name, SUITES)}
            against = previous.get(name) if c.get("group") == "ladder" else (
                c.get("compare_to") or (reference if c.get("group") in ("ablation", "corruption") else None))
            if against and against != name:
                entry["paired_against"] = against
                entry["paired"] = {s: self.paired(name, against, s) for s in self.suites()}
                m, p = entry["mean3"], self.suite_mean(against, SHORT_SUITES)
                entry["delta_mean3"] = m - p if m is not None and p is not None else None
            out["configs"][name] = entry
        out["pooled"] = {}
        for target, names in self.pools().items():
            cells = {s: self.pooled_cell(names, s) for s in self.suites()}
            out["pooled"][target] = {"configs": names, "suites": cells,
                                     "mean3": _suite_mean([cells.get(s, {"mean": None}) for s in SHORT_SUITES]),
                                     "mean4": _suite_mean([cells.get(s, {"mean": None}) for s in SUITES])}
        return out


# ----- paired episodes ------------------------------------------------------------------------------------
PAIRING_KEYS = ("eval_seed", "init_states", "episode_length")


def same_starts(a: dict, b: dict) -> bool:
    """Whether episode i of a task starts from the same state in both runs. From the official init states episode
    i starts from init state i whatever the number of episodes; randomised resets also need the same number."""
    return all(a.get(k) == b.get(k) for k in PAIRING_KEYS) and (
        a.get("init_states") is not False or a.get("n_episodes_per_task") == b.get("n_episodes_per_task"))


def same_model(a: dict, b: dict) -> bool:
    """Whether two runs that load one checkpoint path evaluated the same weights: a training redone in place (its
    checkpoint lost) writes new weights under the old path. Runs of different checkpoints (a baseline against
    PredVLA) compare different models on purpose; records written before `model_sha256` existed pair only with
    each other."""
    return a.get("checkpoint") != b.get("checkpoint") or a.get("model_sha256") == b.get("model_sha256")


def run_episodes(runs_dir: Path, config: str, suite: str, seed: int) -> dict[tuple[str, int], bool]:
    """Success of every evaluated episode of a run by (task id, episode index), from its eval_info.json files."""
    episodes = {}
    for path in sorted(eval_run_dir(runs_dir, config, suite, seed).rglob(EVAL_INFO_FILE)):
        try:
            tasks = episode_successes(path)
        except EvalInfoError as err:
            raise ReportError(str(err)) from err
        episodes.update({(task, i): ok for task, successes in tasks.items() for i, ok in enumerate(successes)})
    return episodes


def sign_test(only_a: int, only_b: int) -> float:
    """Exact two-sided sign test (binomial, p = 1/2) on the pairs that succeed in only one of the two runs."""
    n = only_a + only_b
    return 1.0 if n == 0 else float(binomtest(only_a, n, 0.5).pvalue)


PAIR_COUNTS = ("pairs", "successes", "against_successes", "only", "only_against")  # of a set of episode pairs


def sum_counts(parts: Iterable[dict[str, int]]) -> dict[str, int]:
    """PAIR_COUNTS summed over several sets of episode pairs (tasks, or the configurations of a pool)."""
    return {count: sum(part[count] for part in parts) for count in PAIR_COUNTS}


def paired_episodes(summary: dict, records: list[dict], runs_dir: Path) -> None:
    """Add `episodes` (per suite: pairs, successes, discordant counts, sign test) to every `compare_to` entry."""
    by_run = {(r["config"], r["suite"], int(r["seed"])): r for r in records}
    for name, entry in summary["configs"].items():
        against = entry.get("compare_to")
        if not against:
            continue
        for suite in summary["suites"]:
            comparable = sorted(seed for (c, s, seed), r in by_run.items() if c == name and s == suite
                                and (against, suite, seed) in by_run
                                and same_starts(r, by_run[(against, suite, seed)]))
            seeds = [seed for seed in comparable
                     if same_model(by_run[(name, suite, seed)], by_run[(against, suite, seed)])]
            summary.setdefault("unpaired", []).extend(
                {"config": name, "against": against, "suite": suite, "seed": seed}
                for seed in comparable if seed not in seeds)
            tasks: dict[str, dict[str, int]] = {}  # task -> PAIR_COUNTS over its paired episodes
            for seed in seeds:
                mine, theirs = (run_episodes(runs_dir, c, suite, seed) for c in (name, against))
                for key in mine.keys() & theirs.keys():
                    a, b = mine[key], theirs[key]
                    task = tasks.setdefault(key[0], dict.fromkeys(PAIR_COUNTS, 0))
                    for count, value in zip(PAIR_COUNTS, (1, a, b, a and not b, b and not a), strict=True):
                        task[count] += value
            if tasks:
                counts = sum_counts(tasks.values())
                entry.setdefault("episodes", {})[suite] = {
                    "against": against, "seeds": seeds, **counts,
                    "sign_test_p": sign_test(counts["only"], counts["only_against"]),
                    "tasks": dict(sorted(tasks.items(), key=lambda item: int(item[0])))}
    for pool in summary.get("pooled", {}).values():
        for suite in summary["suites"]:
            parts = [e for name in pool["configs"] if (e := summary["configs"][name].get("episodes", {}).get(suite))]
            if len(parts) < 2:  # one configuration's pairs are already in the table as they are
                continue
            counts = sum_counts(parts)
            pool.setdefault("episodes", {})[suite] = {
                "against": " + ".join(e["against"] for e in parts),
                "seeds": sorted(seed for e in parts for seed in e["seeds"]), **counts,
                "sign_test_p": sign_test(counts["only"], counts["only_against"])}


def episodes_table(summary: dict) -> str | None:
    """Paired episodes of every `compare_to` pair, then of every pool (`pool_with`) over its seeds together."""
    entries = [(name, entry) for name, entry in summary["configs"].items()] + [
        (" + ".join(pool["configs"]), pool) for pool in summary.get("pooled", {}).values()]
    rows = [[name, e["against"], SUITE_LABELS[suite],
             ", ".join(map(str, e["seeds"])), str(e["pairs"]), f"{e['successes']} / {e['against_successes']}",
             f"{e['only']} / {e['only_against']}", f"{e['sign_test_p']:.3g}"]
            for name, entry in entries for suite in summary["suites"]
            if (e := entry.get("episodes", {}).get(suite))]
    notes = [f"Not paired: `{u['config']}` against `{u['against']}`, {SUITE_LABELS[u['suite']]}, seed {u['seed']}: "
             "both load one checkpoint path, but not the same weights (`model_sha256` of their records differs; a "
             "training redone in place). Evaluate both from the new checkpoint to pair them."
             for u in summary.get("unpaired", [])]
    if not rows and not notes:
        return None
    table = [_table(["Model", "against", "suite", "seeds", "episode pairs", "successes (model / against)",
                     "only model / only against", "sign test p"], rows)] if rows else []
    return "\n\n".join(table + notes)


# ----- tables --------------------------------------------------------------------------------------------
def fmt_cell(cell: dict) -> str:
    if cell["n"] == 0:
        return f"{MISSING} (0/{cell['planned']})" if cell["planned"] else MISSING
    # One seed has no spread to show: "72.00 (n = 1)", never "± 0.00".
    text = f"{cell['mean']:.2f} ± {cell['std']:.2f}" if cell["n"] > 1 else f"{cell['mean']:.2f} (n = 1)"
    return text + (f" ({cell['n']}/{cell['planned']} seeds)" if cell["n"] < cell["planned"] else "")


def fmt_num(value: float | None, signed: bool = False) -> str:
    if value is None:
        return MISSING
    return f"{value:+.2f}" if signed else f"{value:.2f}"


def fmt_params(value: int | None) -> str:
    return f"{value:,}" if value is not None else MISSING


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])


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
        for label, params, cells in ((_label(summary, n), c["params"], c), *(
                [(_pooled_label(summary, last_of[n]), summary["configs"][last_of[n]]["params"],
                  summary["pooled"][last_of[n]])] if n in last_of else [])):
            row = [label, fmt_params(params), *[fmt_cell(cells["suites"][s]) for s in short],
                   fmt_num(cells["mean3"])]
            if "libero_10" in suites:
                row += [fmt_cell(cells["suites"]["libero_10"]), fmt_num(cells["mean4"])]
            rows.append(row)
    return _table(header, rows)


def _pools_after(summary: dict, names: list[str]) -> dict[str, str]:
    """`{name: pool target}`: a pool's row (pool_with) follows the last of its configurations in a table of `names`."""
    return {[n for n in names if n in pool["configs"]][-1]: target
            for target, pool in summary.get("pooled", {}).items() if target in names}


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
            rows.append([label, SUITE_LABELS[suite], fmt_cell(ours) if ours else MISSING,
                         f"{mean:.2f}" + (f" ± {std:.2f}" if std is not None else ""),
                         fmt_num(ours["mean"] - mean if ours and ours["mean"] is not None else None, signed=True)])
    return _table(["Model", "suite", "ours", "paper", "ours − paper"], rows) if rows else None


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
        rows.append([n if n != ref else "—", _label(summary, n) + (" (ours)" if n == ref else ""),
                     fmt_params(c["params"]), ratio, *[fmt_cell(c["suites"][s]) for s in suites], fmt_num(mean)])
    return _table(["", "Model", "Params", "vs. ours", *[SUITE_LABELS[s] for s in suites], "Mean"], rows)


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
        rows.append([n, _label(summary, n), fmt_params(c["params"]), *[fmt_cell(c["suites"][s]) for s in short],
                     fmt_num(c["mean3"]), delta])
    return _table(["", "Modification", "Params", *[SUITE_LABELS[s] for s in short], "Mean", "Δ"], rows)


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
    return _table(["", "Change from PredVLA", *[SUITE_LABELS[s] for s in suites]], rows)


def corruption_table(summary: dict) -> str | None:
    names = [n for n, c in summary["configs"].items() if c["group"] == "corruption" and c.get("corruption")]
    if not names:
        return None
    suites = [s for s in summary["suites"] if any(summary["configs"][n]["suites"][s]["n"] for n in names)]
    rows = []
    for n in sorted(names, key=lambda n: (summary["configs"][n]["corruption"].get("channel", ""),
                                          summary["configs"][n]["corruption"].get("alpha", 0))):
        c = summary["configs"][n]
        rows.append([n, str(c["corruption"].get("channel")), str(c["corruption"].get("alpha")),
                     *[fmt_cell(c["suites"][s]) for s in suites]])
    return _table(["", "channel", "α", *[SUITE_LABELS[s] for s in suites]], rows)


# ----- figures -------------------------------------------------------------------------------------------
def _save(fig, path: Path) -> None:
    atomic_save_figure(fig, path, dpi=130, bbox_inches="tight")


def ladder_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    configs = summary["configs"]
    chain, branches = ladder_rungs(summary)
    if not chain:
        return False
    short = [s for s in SHORT_SUITES if s in summary["suites"]]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    x = {n: i for i, n in enumerate(chain)}
    colors = dict(zip(short, ("tab:blue", "tab:orange", "tab:green"), strict=False))

    def value(n: str, s: str | None) -> float:
        v = configs[n]["mean3"] if s is None else configs[n]["suites"][s]["mean"]
        return np.nan if v is None else v

    for s in [*short, None]:
        style = {"color": "black", "linewidth": 3, "label": "3-suite mean"} if s is None else {
            "color": colors[s], "linewidth": 1.2, "label": SUITE_LABELS[s]}
        ax.plot(range(len(chain)), [value(n, s) for n in chain], marker="o", **style)
        for b in branches:
            parent = configs[b].get("paired_against")
            if parent in x:
                bx = x[parent] + 0.5
                ax.plot([x[parent], bx], [value(parent, s), value(b, s)], linestyle="--", marker="s",
                        color=style["color"], linewidth=style["linewidth"] * 0.7)
                if s is None:
                    ax.annotate(b, (bx, value(b, s)), textcoords="offset points", xytext=(5, -10))
    ax.set_xticks(range(len(chain)), chain)
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(0, 100)
    ax.set_title("Ladder: PredVLA to BC-RNN (dashed: side branches)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def params_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    four = "libero_10" in summary["suites"]
    key = "mean4" if four else "mean3"
    ours = [(n, c["params"], c[key]) for n, c in summary["configs"].items()
            if c["group"] in ("main", "baseline") and c["params"] and c[key] is not None]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    baseline_params = [c["params"] for c in summary["configs"].values() if c["group"] == "baseline" and c["params"]]
    if baseline_params:
        ax.axvspan(min(baseline_params) * 0.95, max(baseline_params) * 1.05, color="gray", alpha=0.15,
                   label="controlled baselines (params range)")
    for i, (name, params, success) in enumerate(PUBLISHED_REFERENCES):
        ax.scatter(params, success, marker="^", color="tab:gray", label="published (reported)" if i == 0 else None)
        ax.annotate(name, (params, success), textcoords="offset points", xytext=(5, 4), fontsize=8)
    for name, success in PARAMETERLESS_REFERENCES:
        ax.axhline(success, color="tab:gray", linestyle=":", linewidth=1)
        ax.annotate(f"{name} {success} (params not reported)", (1e7, success), textcoords="offset points",
                    xytext=(0, -11), fontsize=8, color="tab:gray")
    for i, (name, params, success) in enumerate(ours):
        ax.scatter(params, success, marker="o", color="tab:red", zorder=3, label="this sweep" if i == 0 else None)
        ax.annotate(name, (params, success), textcoords="offset points", xytext=(5, -10), fontsize=8, color="tab:red")
    ax.set_xscale("log")
    ax.set_xlim(1e5, 2e10)
    ax.set_ylim(0, 100)
    ax.set_xlabel("trainable policy parameters")
    ax.set_ylabel(f"LIBERO mean success (%) — ours: {'4' if four else '3'}-suite mean")
    ax.set_title("Parameters vs success (published points: reported numbers, not controlled)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(loc="lower right", fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def sensory_ablations(results: Results) -> list[tuple[str, str]]:
    """(config, channel) of the error-channel ablations: eval overrides setting er_lambda_v / er_lambda_q to 0."""
    found = []
    for name, c in results.configs.items():
        overrides = c.get("eval_overrides") or {}
        for field, channel in (("er_lambda_v", "visual"), ("er_lambda_q", "proprioceptive")):
            if field in overrides and float(overrides[field]) == 0.0:
                found.append((name, channel))
    return found


def paired_task_rates(summary: dict, config: str, reference: str, suite: str) -> dict[str, tuple[float, float]] | None:
    """Per task, (reference's success, config's change) in % over the episodes both ran from the same starts
    (`paired_episodes`); None when the two have no paired episodes in the suite."""
    paired = summary["configs"].get(config, {}).get("episodes", {}).get(suite)
    if not paired or paired["against"] != reference:
        return None
    return {task: (100.0 * t["against_successes"] / t["pairs"], 100.0 * (t["successes"] - t["against_successes"])
                   / t["pairs"]) for task, t in paired["tasks"].items()}


def pertask_figure(results: Results, summary: dict, path: Path) -> bool:
    """Per task: the intact model's success (gray) and each sensory ablation's change (colored), on the episodes
    both ran from the same starts where the episodes are recorded (an ablation may run fewer per task than the
    intact model), else the difference of the seeds' per-task rates."""
    import matplotlib.pyplot as plt

    ablations = sensory_ablations(results)
    reference = results.reference()
    if not ablations or reference is None:
        return False
    suites = [s for s in results.suites() if any(results.tasks.get(a, {}).get(s) for a, _ in ablations)]
    if not suites:
        return False
    fig, axes = plt.subplots(1, len(suites), figsize=(5 * len(suites), 4), squeeze=False)
    colors = ("tab:blue", "tab:orange")
    for ax, suite in zip(axes[0], suites, strict=True):
        intact = results.tasks.get(reference, {}).get(suite, {})
        task_ids = sorted({t for seed in intact.values() for t in seed}, key=int)
        base = [np.mean([intact[s][t] for s in intact]) if intact else np.nan for t in task_ids]
        deltas = []
        same_episodes = False  # whether the gray bars are the intact model's success on the first ablation's pairs
        for i, (name, _) in enumerate(ablations):
            paired = paired_task_rates(summary, name, reference, suite)
            if paired is not None:
                deltas.append([paired[t][1] if t in paired else np.nan for t in task_ids])
                if i == 0:
                    base = [paired[t][0] if t in paired else np.nan for t in task_ids]
                    same_episodes = True
                continue
            runs = results.tasks.get(name, {}).get(suite, {})
            seeds = sorted(set(runs) & set(intact))
            deltas.append([np.mean([runs[s][t] - intact[s][t] for s in seeds]) if seeds else np.nan
                           for t in task_ids])
        order = np.argsort(np.nan_to_num(deltas[0], nan=0.0))
        xs = np.arange(len(task_ids))
        width = 0.8 / (1 + len(ablations))
        intact_label = f"{reference} (intact{', same episodes' if same_episodes else ''})"
        ax.bar(xs, np.asarray(base)[order], width, color="lightgray", label=intact_label)
        for i, ((name, channel), delta) in enumerate(zip(ablations, deltas, strict=True)):
            ax.bar(xs + (i + 1) * width, np.asarray(delta)[order], width, color=colors[i % 2],
                   label=f"{name}: change without {channel} error")
        ax.axhline(0, color="black", linewidth=0.8)
        ax.set_xticks(xs + width * len(ablations) / 2, [task_ids[i] for i in order])
        ax.set_xlabel("task id (sorted by the first ablation's change)")
        ax.set_title(SUITE_LABELS[suite])
        ax.set_ylim(-100, 100)
    axes[0][0].set_ylabel("success (%) / change (points)")
    axes[0][-1].legend(fontsize=7, loc="lower right")
    _save(fig, path)
    plt.close(fig)
    return True


def corruption_figure(summary: dict, path: Path) -> bool:
    import matplotlib.pyplot as plt

    configs = summary["configs"]
    names = [n for n, c in configs.items() if c["group"] == "corruption" and c.get("corruption")]
    if not names:
        return False
    suites = [s for s in summary["suites"] if any(configs[n]["suites"][s]["n"] for n in names)]
    if not suites:
        return False
    fig, axes = plt.subplots(1, len(suites), figsize=(4.5 * len(suites), 3.8), squeeze=False)
    channels = sorted({configs[n]["corruption"].get("channel") for n in names})
    for ax, suite in zip(axes[0], suites, strict=True):
        for channel, color in zip(channels, ("tab:blue", "tab:orange", "tab:green"), strict=False):
            points = []
            for n in names:
                spec = configs[n]["corruption"]
                cell = configs[n]["suites"][suite]
                if spec.get("channel") == channel and cell["n"]:
                    points.append((float(spec["alpha"]), cell["mean"], cell["std"]))
            intact = configs.get(configs[names[0]].get("paired_against") or "", {}).get("suites", {}).get(suite)
            if intact and intact["n"]:
                points.append((0.0, intact["mean"], intact["std"]))
            points.sort()
            if points:
                a, m, sd = (np.asarray(v) for v in zip(*points, strict=True))
                ax.plot(a, m, marker="o", color=color, label=str(channel))
                ax.fill_between(a, m - sd, m + sd, color=color, alpha=0.2)
        open_loop = {configs[n]["corruption"].get("open_loop") for n in names} - {None}
        for ref in open_loop:
            cell = configs.get(ref, {}).get("suites", {}).get(suite)
            if cell and cell["n"]:
                ax.axhline(cell["mean"], color="black", linestyle="--", linewidth=1, label=f"open loop ({ref})")
        ax.set_xlabel("α (fraction of observations replaced)")
        ax.set_title(SUITE_LABELS[suite])
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success rate (%)")
    axes[0][-1].legend(fontsize=8)
    _save(fig, path)
    plt.close(fig)
    return True


def task_ids(results: Results, suite: str) -> list[str]:
    return sorted({t for by_suite in results.tasks.values() for seeds in by_suite.get(suite, {}).values()
                   for t in seeds}, key=int)


def task_table(results: Results, suite: str) -> str | None:
    """Success per task (mean over seeds, %) of every configuration evaluated on `suite`."""
    names = [n for n in results.configs if results.tasks.get(n, {}).get(suite)]
    ids = task_ids(results, suite)
    if not names or len(ids) < 2:
        return None
    rows = []
    for name in names:
        seeds = results.tasks[name][suite]
        rows.append([name, *[fmt_num(np.mean([seeds[s][t] for s in seeds if t in seeds[s]]))
                             if any(t in seeds[s] for s in seeds) else MISSING for t in ids],
                     fmt_num(np.mean([results.rates[name][suite][s] for s in seeds]))])
    return _table(["Model", *[f"task {t}" for t in ids], "mean"], rows)


def task_figure(results: Results, path: Path) -> bool:
    """Per task of every multi-task suite: each configuration's success, side by side."""
    import matplotlib.pyplot as plt

    suites = [s for s in results.suites() if task_table(results, s) is not None]
    if not suites:
        return False
    fig, axes = plt.subplots(len(suites), 1, figsize=(10, 3.6 * len(suites)), squeeze=False)
    for ax, suite in zip(axes[:, 0], suites, strict=True):
        names = [n for n in results.configs if results.tasks.get(n, {}).get(suite)]
        ids = task_ids(results, suite)
        width = 0.8 / len(names)
        for i, name in enumerate(names):
            seeds = results.tasks[name][suite]
            values = [np.mean([seeds[s][t] for s in seeds if t in seeds[s]] or [np.nan]) for t in ids]
            ax.bar(np.arange(len(ids)) + i * width, values, width, label=results.configs[name].get("label") or name)
        ax.set_xticks(np.arange(len(ids)) + width * (len(names) - 1) / 2, ids)
        ax.set_xlabel("task id")
        ax.set_ylabel("success (%)")
        ax.set_ylim(0, 100)
        ax.set_title(SUITE_LABELS[suite])
        ax.grid(axis="y", alpha=0.3)
    axes[0][0].legend(fontsize=7, ncol=2)
    _save(fig, path)
    plt.close(fig)
    return True


def _relative(command: list[str]) -> str:
    """A recorded command as a reader runs it from the repository root (no machine-specific prefixes)."""
    prefixes = (f"{Path(sys.executable).parent}/", f"{Path.cwd()}/")
    words = []
    for word in command:
        for prefix in prefixes:
            word = word.replace(prefix, "")
        words.append(f"'{word}'" if "[" in word else word)
    return " ".join(words)


def _stage_commands(command: list[str] | list[list[str]]) -> str:
    """A data stage's command, or the commands of the processes that shared its work (run side by side)."""
    commands = command if command and isinstance(command[0], list) else [command]
    return " and ".join(f"`{_relative(c)}`" for c in commands)


def _training_minutes(record: dict, runs_dir: Path, read: dict[Path, list[TrainingRun]]) -> str:
    """A record's training wall time: from its training's log, over every `lerobot-train` call (the record's
    `train_wall_s` times the last call only), else the record's; the number of calls where there were several.
    `read`: the logs parsed so far (the records that evaluate one training share its log)."""
    trained = record.get("checkpoint_from") or record["config"]
    log = run_log_path(runs_dir, trained, record["suite"], record["seed"], "train")
    if log not in read:
        read[log] = training_runs(log.read_text(errors="replace")) if log.is_file() else []
    runs = read[log]
    wall = sum(r.wall_s for r in runs) if runs else record.get("train_wall_s")
    if not wall:
        return MISSING
    return f"{wall / 60:.0f}" + (f" ({len(runs)} calls)" if len(runs) > 1 else "")


def stages_section(records: list[dict], runs_dir: Path) -> list[str]:
    """Wall time of every recorded stage (data, training, evaluation) and the exact commands."""
    lines = []
    for path in sorted((Path(runs_dir) / "data").glob("*.json")):
        stages = _load_json(path)
        lines += [f"Data stages of {path.stem}:", "",
                  _table(["stage", "wall time (min)", "command"],
                         [[k, f"{v['wall_s'] / 60:.1f}", _stage_commands(v["command"])] for k, v in stages.items()]),
                  ""]
    rows, commands, training_logs = [], [], {}
    for r in sorted(records, key=lambda r: (r["config"], r["suite"], int(r["seed"]))):
        episodes = sum(t["episodes"] for t in r["tasks"].values())
        rows.append([r["config"], r["suite"], str(r["seed"]), str(r.get("steps", MISSING)),
                     _training_minutes(r, runs_dir, training_logs),
                     f"{r['eval_wall_s'] / 60:.0f}" if r.get("eval_wall_s") else MISSING, str(episodes)])
        cmd = r.get("commands") or {}
        if cmd.get("train") and not r.get("checkpoint_from"):
            commands.append(f"- `{r['config']}` training: `{_relative(cmd['train'])}`")
        if cmd.get("eval"):
            commands.append(f"- `{r['config']}` evaluation, one task per call: `{_relative(cmd['eval'][0])}`")
    if not rows:
        return []
    lines += [_table(["config", "suite", "seed", "training steps", "training (min)", "evaluation (min)",
                      "episodes"], rows),
              "", "Training: the `lerobot-train` calls in its log together (a training resumed after a stop has "
              "several; from the timestamps of their lines, short by less than a logging interval each). "
              "Evaluation: its finished parts together (with several workers, more than the time that passed)."]
    if commands:
        lines += ["", "Commands, as recorded (paths relative to the repository root):", "", *commands]
    return lines


def fresh_clone_section(runs_dir: Path) -> list[str]:
    """What a fresh clone of the repository recomputes and what it reads, stage by stage: the data stages (their
    outputs are never committed), and each finished training, whose model is read where its record names one outside
    the runs directory's `train/` (committed, e.g. by the sweep's `train.publish`) and is otherwise redone (its
    checkpoints stay on the machine that trained it), except a learning-rate candidate whose held-out result is
    committed: the sweep reads that result and never needs the candidate's model again."""
    runs_dir = Path(runs_dir).resolve()
    candidate_results = {
        (candidate_name(path.parent.parent.name, json.loads(path.read_text())["lr"]), path.parent.name): path
        for path in (runs_dir / LR_SWEEP_DIR).glob(f"*/*/{CANDIDATE_PREFIX}*.json")}
    rows = []
    for path in sorted((runs_dir / "data").glob("*.json")):
        stages = _load_json(path)
        minutes = sum(v["wall_s"] for v in stages.values()) / 60
        rows.append([f"data of {path.stem} ({', '.join(stages)})",
                     f"recomputed from the sweep file ({minutes:.0f} min as recorded); needed only to train"])
    for path in sorted((runs_dir / "train").glob(f"*/*/seed*/{TRAIN_DONE_FILE}")):
        trained = _load_json(path)
        checkpoint = (runs_dir / trained["checkpoint"]).resolve()
        config, suite, seed = path.parts[-4], path.parts[-3], path.parts[-2].removeprefix("seed")
        local = checkpoint.is_relative_to(runs_dir / "train")
        result = candidate_results.get((config, suite))
        if result is not None:
            done = f"not needed: its held-out result is read from `{_relative([str(result)])}`"
        elif local:
            done = f"redone ({trained['steps']:,} steps): its checkpoint stays on the machine that trained it"
        else:
            done = f"read from `{_relative([str(checkpoint)])}`"
        rows.append([f"training {config} / {suite} / seed {seed}", done])
    if not rows:
        return []
    return ["", "## On a fresh clone", "",
            "Every stage is skipped when its output exists; run records, `eval_info.json` files and logs are "
            "committed, so a fresh clone runs only the missing runs, and these stages where a missing run needs them:",
            "", _table(["stage", "on a fresh clone"], rows)]


# ----- report ----------------------------------------------------------------------------------------------
def starts_section(path: Path) -> list[str]:
    """The demonstrations' starts against the official init states (mean over tasks of `start_spread.json`)."""
    if not path.is_file():
        return []
    tasks = json.loads(path.read_text())["tasks"]

    def mean(kind: str, key: str) -> float:
        return float(np.mean([t[kind][key] if key == "joint_std" else np.mean(list(t[kind][key].values()))
                              for t in tasks.values()]))

    gap_mm = max(1000 * float(np.abs(np.subtract(t["demonstrations"]["object_mean"][o],
                                                 t["official"]["object_mean"][o])).max())
                 for t in tasks.values() for o in t["official"]["object_mean"])
    return ["", "## Demonstrations' starts", "",
            f"The demonstrations' first simulator states against the official init states, mean over {len(tasks)} "
            f"tasks (`{path.name}`); every object's mean position lies within {gap_mm:.1f} mm of the official one.",
            "", _table(["", "demonstrations", "official init states"], [
                ["arm joints, std over starts (rad)", f"{mean('demonstrations', 'joint_std'):.4f}",
                 f"{mean('official', 'joint_std'):.4f}"],
                ["objects, std of x, y over starts (mm)", f"{1000 * mean('demonstrations', 'object_std'):.2f}",
                 f"{1000 * mean('official', 'object_std'):.2f}"]])]


def mechanism_rows(history: list[dict]) -> list[list[str]]:
    """One row per inspected checkpoint of `predvla inspect`'s history."""
    rows = []
    for h in history:
        lang, removed, post = h["language"], h["proprio_error_per_dim"].get("removed"), h.get("posteriors")
        rows.append([
            f"{h['step']:,}" if h.get("step") is not None else MISSING,
            f"{100 * lang['open_loop_picks_own_task']:.0f}",
            f"{lang['mean_language_swap_mse']:.3f} / {lang['mean_demo_gap']:.3f}",
            " / ".join(f"{100 * removed[k]:.0f}" if k in removed else MISSING for k in ("proprio", "vision", "action"))
            if removed else MISSING,
            " / ".join(f"{post[m]['prior_gap']:.3f}" for m in MODULE_NAMES) if post else MISSING,
        ])
    return rows


def mechanism_section(out: Path) -> list[str]:
    """Per training seed inspected beside the report (`inspect/seed<N>/inspect.json`): the mechanism's numbers per
    checkpoint and the figure over training."""
    found = sorted((p for p in (out / INSPECT_DIR).glob("seed*/inspect.json") if p.parent.name[4:].isdigit()),
                   key=lambda p: int(p.parent.name[4:]))  # seed<N>/: one seed over training, not single checkpoints
    if not found:
        return []
    lines = ["", "## The mechanism over training", "",
             "`predvla inspect` on the training checkpoints, without the simulator: how often the exact open loop is "
             "closest to its own task's mean demonstration (%, chance: one task in the number of tasks); how far "
             "swapping the instruction moves the open-loop actions, against how far the tasks' mean demonstrations "
             "lie apart (action MSE); the open-loop error the training posteriors remove (%, proprioceptive / "
             "visual prediction, action against the demonstrated one); the training prior-posterior gap per "
             "module (" + " / ".join(MODULE_NAMES) + ")."]
    for path in found:
        seed = path.parent.name
        lines += ["", f"### {seed}", "", _table(["step", "open loop picks own task (%)", "language swap / demo gap",
                                                 "error removed (%)", "prior gap"],
                                                mechanism_rows(json.loads(path.read_text())["history"]))]
        if (path.parent / CURVES_FIGURE).is_file():
            lines += ["", f"![{seed} over training]({INSPECT_DIR}/{seed}/{CURVES_FIGURE})"]
    return lines


def lr_selection_section(runs_dir: Path) -> list[str]:
    """The baselines' learning rates, chosen on held-out demonstrations (`RUNS_DIR/lr_sweep/<config>/<suite>.json`
    of `predvla sweep`); a sweep still running shows its finished candidates
    (`RUNS_DIR/lr_sweep/<config>/<suite>/lr<rate>.json`)."""
    selections = [json.loads(path.read_text()) for path in sorted((Path(runs_dir) / LR_SWEEP_DIR).glob("*/*.json"))]
    selections += pending_selections(runs_dir)
    if not selections:
        return []
    rates = sorted({rate for sel in selections for rate in sel["heldout_nll"]}, key=float)

    def nll(sel: dict, rate: str) -> str:
        if rate not in sel["heldout_nll"]:
            return NOT_RUN
        return MISSING if sel["heldout_nll"][rate] is None else f"{sel['heldout_nll'][rate]:.3f}"

    def pending(sel: dict) -> str:
        done = len(sel["heldout_nll"])
        return f"pending ({done} candidate{'s' * (done != 1)} done)"

    rows = [[sel["config"], SUITE_LABELS.get(sel["suite"], sel["suite"]), *[nll(sel, r) for r in rates],
             f"{sel['chosen_lr']:g}" if "chosen_lr" in sel else pending(sel),
             f"{sel['steps']:,}",
             str(sum(len(v) for v in sel["heldout_episodes"].values())) if "heldout_episodes" in sel else MISSING]
            for sel in selections]
    return ["", "## Baselines' learning rates", "",
            "Each baseline's learning rate is the one of lowest action NLL on held-out demonstrations (LeRobot's "
            "`--dataset.eval_split`), never on the evaluation's init states; the candidates train on the other "
            f"demonstrations ({MISSING}: diverged; {NOT_RUN}: a candidate of a sweep still running).", "",
            _table(["config", "suite", *[f"NLL at lr {r}" for r in rates], "chosen", "candidate steps",
                    "held-out demonstrations"], rows)]


def write_report(runs_dir: Path, out: Path) -> dict:
    """Build tables, figures, `report.md` and `report.json` in `out`; returns the summary."""
    import matplotlib

    matplotlib.use("Agg")
    records = load_records(runs_dir)
    plan_path = Path(runs_dir) / "plan.json"
    results = Results.build(records, _load_json(plan_path) if plan_path.is_file() else None)
    summary = results.summary()
    paired_episodes(summary, records, Path(runs_dir))
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
    missing = [f"{name}/{suite}/seed{seed}" for name, c in summary["configs"].items()
               for suite, cell in c["suites"].items() for seed in cell["missing_seeds"]]
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
        ("Beside the paper", paper_table(summary), None,
         "The paper's published success of the same configuration (its Tables 3-6: mean ± standard deviation over "
         "its seeds) beside ours."),
        ("Trainable parameters vs success", None, "params",
         "Published points are reported numbers with different protocols, for scale only."),
        ("Ladder", ladder_table(summary), "ladder",
         "Δ: change in the 3-suite mean relative to the preceding rung (side branches: relative to their parent)."),
        ("Ablations", ablation_table(summary), "pertask",
         "Δ: success minus that of the run named (its `compare_to`, else the intact model), mean over the seeds "
         "both have (n), each run's rate over its own episodes; where the two ran different numbers of episodes, "
         "the paired episodes below compare only those both ran."),
        ("Paired episodes", episodes_table(summary), None,
         "Each episode against the same start of the compared run (same evaluation seed, resets and protocol); "
         "sign test: exact, two-sided, on the episodes that succeed in only one."),
        ("Corrupted observations", corruption_table(summary), "corruption",
         "α: fraction of observations replaced; bands ±1 seed standard deviation; dashed: open loop."),
        *[(f"Per task: {SUITE_LABELS[suite]}", task_table(results, suite), "tasks" if i == 0 else None,
           "Success per task (%), mean over seeds.") for i, suite in enumerate(
              s for s in results.suites() if task_table(results, s) is not None)],
    ):
        has_figure = figure in summary["figures"]
        if table is None and not has_figure:
            continue
        sections += ["", f"## {title}", "", note]
        if table is not None:
            sections += ["", table]
        if has_figure:
            sections += ["", f"![{title}]({FIGURES[figure]})"]
    sections += starts_section(out / START_SPREAD_FILE) + mechanism_section(out) + lr_selection_section(runs_dir)
    stages = stages_section(records, runs_dir)
    if stages:
        sections += ["", "## Stages: wall time and commands", "", *stages]
    sections += fresh_clone_section(runs_dir)
    if missing:
        sections += ["", "## Missing runs", "", f"{len(missing)} planned runs have no record:", "",
                     *[f"- `{m}`" for m in missing]]
    atomic_write_text(out / REPORT_FILE, "\n".join(sections) + "\n")
    atomic_write_json(out / SUMMARY_FILE, summary)
    return summary
