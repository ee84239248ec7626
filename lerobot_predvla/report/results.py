"""Loading what `predvla report` reads: the run records and plan of a sweep's RUNS_DIR, each run's evaluated
episodes (its `eval_info.json` files), and a written report's `report.json`; `Results` holds the records' success
rates by configuration, suite and seed."""

import json
from dataclasses import dataclass
from pathlib import Path

from lerobot_predvla.sims.libero.protocol import SHORT_SUITES
from lerobot_predvla.sweep.eval_info import EVAL_INFO_FILE, EvalInfoError, episode_successes, recorded_unsettled
from lerobot_predvla.sweep.layout import PLAN_FILE, RECORDS_DIR, eval_run_dir
from lerobot_predvla.utils.statistics import success_rate, task_rates

SUMMARY_FILE = "report.json"


class ReportError(ValueError):
    """No usable records, or a malformed record or plan."""


def load_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ReportError(f"{path}: unreadable JSON ({err}).") from err


def load_records(runs_dir: Path) -> list[dict]:
    records_dir = Path(runs_dir) / RECORDS_DIR
    paths = sorted(records_dir.rglob("*.json")) if records_dir.is_dir() else []
    if not paths:
        raise ReportError(f"{records_dir}: no run records (*.json); run `predvla sweep ... --runs-dir {runs_dir}`.")
    records = []
    for path in paths:
        record = load_json(path)
        missing = [k for k in ("config", "suite", "seed", "tasks") if k not in record]
        if missing:
            raise ReportError(f"{path}: not a sweep run record (missing {missing}).")
        records.append(record)
    return records


def load_plan(runs_dir: Path) -> dict | None:
    """The sweep's `plan.json`, None when RUNS_DIR has none."""
    path = Path(runs_dir) / PLAN_FILE
    return load_json(path) if path.is_file() else None


def load_summary(path: Path) -> dict:
    """The `report.json` of a report directory (or the file itself)."""
    path = Path(path)
    path = path / SUMMARY_FILE if path.is_dir() else path
    if not path.is_file():
        raise ReportError(f"{path}: no {SUMMARY_FILE}; run `predvla report RUNS_DIR --out REPORT_DIR` first.")
    return load_json(path)


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


def unsettled_keys(record: dict) -> set[tuple[str, int]] | None:
    """The (task id, episode index) of a run's episodes whose shifted object did not settle where it was put (as
    `run_episodes` keys them): none for a run without shifted objects; None when its record does not tell which
    (`recorded_unsettled`)."""
    if not record.get("object_shift"):
        return set()
    unsettled = recorded_unsettled(record)
    return None if unsettled is None else {(task, i) for task, episodes in unsettled.items() for i in episodes}


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
            rates.setdefault(r["config"], {}).setdefault(r["suite"], {})[int(r["seed"])] = success_rate(r["tasks"])
            tasks.setdefault(r["config"], {}).setdefault(r["suite"], {})[int(r["seed"])] = task_rates(r["tasks"])
            configs.setdefault(
                r["config"],
                {
                    k: r.get(k)
                    for k in ("group", "label", "compare_to", "pool_with", "pool_sets", "branch", "corruption",
                              "eval_overrides")
                },
            )
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
        protocol = (
            f"{'/'.join(map(str, episodes)) or '?'} rollouts per task, {'/'.join(map(str, caps)) or '?'}-step cap"
        )
        return cls(rates, tasks, planned, configs, params, protocol)

    def suites(self) -> list[str]:
        present = {s for by_suite in self.planned.values() for s in by_suite} | {
            s for by_suite in self.rates.values() for s in by_suite
        }
        return [s for s in (*SHORT_SUITES, "libero_10") if s in present]

    def pools(self) -> dict[str, list[str]]:
        """Each configuration that others name in `pool_with`, with them: `{target: [target, *members]}`."""
        pools: dict[str, list[str]] = {}
        for name, c in self.configs.items():
            if c.get("pool_with") in self.configs:  # a target neither planned nor recorded has no row to join
                pools.setdefault(c["pool_with"], [c["pool_with"]]).append(name)
        return pools

    def set_pools(self) -> dict[str, list[str]]:
        """Each configuration with `pool_sets`, with the configurations it lists that were planned or recorded:
        `{target: [target, *listed]}`."""
        return {name: [name, *(n for n in c["pool_sets"] if n in self.configs)]
                for name, c in self.configs.items() if c.get("pool_sets")}

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


def task_ids(results: Results, suite: str) -> list[str]:
    return sorted(
        {t for by_suite in results.tasks.values() for seeds in by_suite.get(suite, {}).values() for t in seeds}, key=int
    )
