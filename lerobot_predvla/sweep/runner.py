"""The sweep runner: every run of a sweep (or of this shard's training units), each checkpoint trained once and
evaluated by every run that uses it, runs whose record holds the tasks asked for skipped; `plan.json` lists what was
planned."""

import json
from dataclasses import asdict

from tqdm import tqdm

from lerobot_predvla.sweep.evaluation import Evaluation
from lerobot_predvla.sweep.layout import PLAN_FILE, TRAIN_DONE_FILE
from lerobot_predvla.sweep.spec import ConfigSpec, Run, SweepError
from lerobot_predvla.sweep.training import Training
from lerobot_predvla.sweep.workspace import SweepStopped
from lerobot_predvla.utils.checkpoints import last_pretrained
from lerobot_predvla.utils.io import atomic_write_json


class Runner(Training, Evaluation):
    """Executes the runs of a sweep under `runs_dir`: `Runner(sweep, runs_dir, execute=...)`, `execute` injectable
    (tests use a fake)."""

    def write_plan(self, runs: list[Run], configs: list[str] | None = None) -> None:
        """`plan.json`: every run of the sweep and its configuration, so the report can mark missing runs.

        The runs already planned in RUNS_DIR are kept (those of configurations the sweep file still has): a later
        call restricted by `--seeds`, `--suites` or `--configs` adds the runs it runs (with `--configs`, only those
        configurations': `--configs X --seeds 1` plans no other configuration at seed 1) instead of replacing the
        plan. Only the call's `configs` (all when None) are described afresh; the others keep their earlier
        descriptions, so a call with `--n-episodes` or `--steps` does not rewrite the protocol of configurations it
        does not run. A configuration's own seeds, narrowed by `--seeds`, are described with the seeds planned
        before (as its runs are kept).
        """
        path = self.runs_dir / PLAN_FILE
        try:
            earlier = json.loads(path.read_text()) if path.is_file() else {"runs": [], "configs": {}}
            planned = [Run(**r) for r in earlier["runs"] if r["config"] in self.sweep.configs]
            described = dict(earlier.get("configs", {}))
        except (ValueError, KeyError, TypeError) as err:
            raise SweepError(
                f"{path}: expected a sweep plan with a list of runs {{config, suite, seed}} ({err}); "
                "delete it to plan from the sweep file alone"
            ) from err
        runs = planned + [r for r in runs if r not in planned]
        fresh = set(configs or self.sweep.configs)

        def describe(name: str, spec: ConfigSpec) -> dict:
            if name not in fresh and name in described:
                return described[name]
            earlier_seeds = described.get(name, {}).get("seeds")
            if spec.seeds is None or not earlier_seeds:
                return asdict(spec)
            return {**asdict(spec), "seeds": sorted(set(spec.seeds) | set(earlier_seeds))}

        atomic_write_json(
            path,
            {
                "runs": [asdict(r) for r in runs],
                "configs": {name: describe(name, spec) for name, spec in self.sweep.configs.items()},
                "protocol": earlier["protocol"]
                if configs and "protocol" in earlier
                else {
                    "n_episodes": self.sweep.settings.n_episodes,
                    "episode_length": self.sweep.settings.episode_length,
                },
            },
        )

    def shard_units(
        self, configs: list[str] | None, shard: tuple[int, int]
    ) -> list[tuple[tuple[str, str, int], list[Run]]]:
        """This shard's training units: every n-th checkpoint, with all runs that evaluate it."""
        return [u for i, u in enumerate(self.sweep.units(self.sweep.runs(configs))) if i % shard[1] == shard[0]]

    def pending_commands(self, configs: list[str] | None, shard: tuple[int, int]) -> list[list[str]]:
        """The commands `run` would start now (for --dry-run); a resumed training shows its resume command."""
        commands, data_done, selected = [], set(), set()
        for (trained, suite, seed), unit_runs in self.shard_units(configs, shard):
            pending = [r for r in unit_runs if not self.is_recorded(r)]
            if not pending:
                continue
            out = self.train_dir(trained, suite, seed)
            if suite not in data_done and not (out / TRAIN_DONE_FILE).is_file():
                # A shared front end's demonstrations and fit are in the data stage of each of its suites: list once.
                commands += [c for _, c in self.data_commands(suite) if c not in commands]
                data_done.add(suite)
            if (out / TRAIN_DONE_FILE).is_file():
                checkpoint = self.evaluable_checkpoint(json.loads((out / TRAIN_DONE_FILE).read_text()), out)
                if checkpoint is None:
                    continue
            else:
                if (trained, suite) not in selected:  # one selection serves every seed
                    commands += self.pending_lr_commands(self.sweep.configs[trained], suite)
                    selected.add((trained, suite))
                spec = self.sweep.configs[trained]
                commands.append(self.pending_train_command(spec, suite, seed))
                checkpoint = last = last_pretrained(out)
                if self.sweep.settings.publish:
                    checkpoint = self.publish_dir(spec, suite, seed)
                    commands.append(self.publish_command(checkpoint, last))
            commands += [command for run in pending for command in self.pending_eval_commands(run, checkpoint)]
        return commands

    def run(
        self, configs: list[str] | None = None, shard: tuple[int, int] = (0, 1), progress: bool = True,
        train_only: bool = False,
    ) -> dict[str, list[str]]:
        """Run (or skip) this shard's runs. Returns run keys by outcome: done, skipped, failed, and with `train_only`
        (train what the pending runs need, evaluate nothing) `trained`: the trainings (config/suite/seed) that are
        finished and evaluable. Once `stop_at` has passed no stage starts: `stopped` then holds why (one line), and
        the runs left are in none of the lists."""
        self.write_plan(self.sweep.runs(configs), configs)
        units = self.shard_units(configs, shard)
        outcome: dict[str, list[str]] = {"done": [], "skipped": [], "failed": [], "stopped": []}
        if train_only:
            outcome["trained"] = []
        bar = tqdm(total=sum(len(r) for _, r in units), desc=f"sweep shard {shard[0]}/{shard[1]}", disable=not progress)
        try:
            self.run_units(units, outcome, bar, train_only)
        except SweepStopped as stop:
            outcome["stopped"].append(str(stop))
        bar.close()
        return outcome

    def run_units(self, units: list, outcome: dict[str, list[str]], bar: tqdm, train_only: bool) -> None:
        """`run`'s loop: per training unit, its training (or its finished record), then its pending evaluations."""
        for (trained, suite, seed), unit_runs in units:
            pending = [r for r in unit_runs if not self.is_recorded(r)]
            outcome["skipped"] += [r.key for r in unit_runs if r not in pending]
            bar.update(len(unit_runs) - len(pending))
            if not pending:
                continue
            trained_spec = self.sweep.configs[trained]
            train_result = self.train(trained_spec, suite, seed)
            if (
                train_result is not None
                and self.evaluable_checkpoint(train_result, self.train_dir(trained, suite, seed)) is None
            ):
                train_result = None
            if train_only:
                outcome["trained" if train_result is not None else "failed"].append(f"{trained}/{suite}/seed{seed}")
                bar.update(len(pending))
                continue
            for run in pending:
                bar.set_postfix_str(run.key)
                ok = train_result is not None and self.evaluate(run, train_result)
                outcome["done" if ok else "failed"].append(run.key)
                bar.update(1)
