"""The evaluation stages of a sweep: `lerobot-eval` of each run, whole or one part per task (`eval.tasks`), parts
run `eval.workers` at once, each finished part kept when a run is redone; the run's record once every part has its
`eval_info.json`.

A record covers the tasks its calls evaluated (`eval_tasks`: the task ids, or None for the whole suite at once). A
later call for other tasks (`--eval-tasks`) evaluates those and adds them to the record, never skipping a task it was
asked for because the run has a record; a record evaluated under another protocol or model is not extended (the run
fails, naming the field)."""

import json
import shutil
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime
from pathlib import Path

from lerobot_predvla import lerobot_commands
from lerobot_predvla.sweep.eval_info import (
    EVAL_INFO_FILE,
    EvalInfoError,
    parse_eval_info,
    recorded_unsettled,
    unsettled_episodes,
)
from lerobot_predvla.sweep.layout import EVAL_WALL_FILE
from lerobot_predvla.sweep.spec import ConfigSpec, Run, SweepError
from lerobot_predvla.sweep.workspace import Workspace, describe_exit
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.manifest import sha256_file
from lerobot_predvla.utils.statistics import episode_totals, percent
from lerobot_predvla.utils.versions import machine, openblas_coretype, run_versions


def part_machine() -> str:
    """The machine an evaluation part runs on and numpy's OpenBLAS kernels (the simulator's controller rounds by
    them): "AMD EPYC, 2 logical CPUs, AVX-512 bf16: no; OpenBLAS Haswell"."""
    return f"{machine()}; OpenBLAS {openblas_coretype()}"


class Evaluation(Workspace):
    """Evaluates the runs of a sweep and writes their records."""

    def eval_command(
        self, run: Run, checkpoint: Path, out: Path | None = None, extra: list[str] | tuple[str, ...] = ()
    ) -> list[str]:
        """The run's `lerobot-eval` into its evaluation folder, or into part folder `out` with the part's `extra`
        arguments."""
        s = self.sweep.settings
        spec = self.sweep.configs[run.config]
        return lerobot_commands.eval_command(
            program=self.lerobot_eval,
            checkpoint=checkpoint,
            device=s.eval_device,
            policy=[*lerobot_commands.field_args(spec.eval_overrides), *self.corruption_args(spec, run.suite)],
            env_type=s.env_type,
            suite=spec.env_task(run.suite),
            episode_length=s.episode_length,
            init_states=spec.init_states,
            n_episodes=spec.n_episodes or s.n_episodes,
            batch_size=s.eval_batch_size,
            seed=run.seed if spec.eval_seed is None else spec.eval_seed,
            output_dir=out or self.eval_dir(run),
            extra=[*s.eval_args, *spec.eval_args, *spec.shift_args(), *extra],
        )

    def corruption_args(self, spec: ConfigSpec, suite: str) -> list[str]:
        """`--policy.er_corruption_*` for a corruption point: the unrelated episode from the source suite's dataset."""
        if spec.corruption is None:
            return []
        source = self.sweep.settings.datasets[self.sweep.corruption_source(spec, suite)]
        return lerobot_commands.field_args(
            {
                "er_corruption_channel": spec.corruption["channel"],
                "er_corruption_alpha": float(spec.corruption["alpha"]),
                "er_corruption_root": str(self.sweep_path(source["root"])),
                "er_corruption_episode": int(spec.corruption.get("episode", 0)),
            }
        )

    def eval_parts(self, run: Run) -> list[tuple[Path, list[str]]]:
        """(output directory, extra lerobot-eval arguments) of each part of a run's evaluation: the whole suite
        at once, or one part per task with `eval.tasks`, each finished part kept when the run is redone."""
        out = self.eval_dir(run)
        tasks = self.sweep.settings.eval_tasks
        if tasks is None:
            return [(out, [])]
        return [(out / f"task{t}", [f"--env.task_ids=[{t}]"]) for t in tasks]

    def read_record(self, run: Run) -> dict:
        """The run's record; a file that is not one is named, with what to do."""
        path = self.record_path(run)
        try:
            record = json.loads(path.read_text())
            if not isinstance(record.get("tasks"), dict):
                raise ValueError("no `tasks` object")
        except (OSError, ValueError, AttributeError) as err:
            raise SweepError(f"{path}: expected a run record with per-task results ({err}); move it aside to "
                             "evaluate the run again") from err
        return record

    def is_recorded(self, run: Run) -> bool:
        """Whether the run's record holds every task this call evaluates: each of `eval.tasks`, or, without them,
        the whole suite (a record written before records named their tasks counts as the whole suite)."""
        if not self.record_path(run).is_file():
            return False
        record, tasks = self.read_record(run), self.sweep.settings.eval_tasks
        if tasks is None:
            return record.get("eval_tasks") is None
        return {str(t) for t in tasks} <= set(record["tasks"])

    def pending_eval_commands(self, run: Run, checkpoint: Path) -> list[list[str]]:
        return [
            self.eval_command(run, checkpoint, out, extra)
            for out, extra in self.eval_parts(run)
            if not (out / EVAL_INFO_FILE).is_file()
        ]

    def evaluate_part(self, run: Run, command: list[str], out: Path, log: Path) -> bool:
        """One part of an evaluation (the whole suite or one task), skipped when its `eval_info.json` exists; its
        wall time is kept beside it."""
        if (out / EVAL_INFO_FILE).is_file():
            return True
        self.check_stop_at(f"evaluation {run.key} ({out.name})")
        shutil.rmtree(out, ignore_errors=True)  # a killed evaluation is redone from scratch
        start = time.monotonic()
        code = self.execute(command, log)
        if code != 0 or not (out / EVAL_INFO_FILE).is_file():
            print(
                f"predvla sweep: evaluation {run.key} ({out.name}) failed ({describe_exit(code)}); see {log}",
                file=sys.stderr,
            )
            return False
        # where the part ran: parts of one run may run on different machines (a run resumed elsewhere)
        atomic_write_json(out / EVAL_WALL_FILE, {"eval_wall_s": round(time.monotonic() - start, 1),
                                                 "machine": part_machine()})
        return True

    def evaluate(self, run: Run, trained: dict) -> bool:
        """Evaluate a run part by part, `eval_workers` parts at once (each with its own log when several run), and
        write its record once every part has its `eval_info.json`: with `eval.tasks` and an earlier record of the
        same model and protocol, the record extended by this call's tasks."""
        spec = self.sweep.configs[run.config]
        checkpoint = self.trained_checkpoint(trained)
        protocol = {
            "model_sha256": sha256_file(checkpoint / "model.safetensors"),
            "n_episodes_per_task": spec.n_episodes or self.sweep.settings.n_episodes,
            "episode_length": self.sweep.settings.episode_length,
            "eval_seed": run.seed if spec.eval_seed is None else spec.eval_seed,
            "eval_overrides": spec.eval_overrides,
            "init_states": spec.init_states,
            "corruption": spec.corruption,
            "object_shift": spec.object_shift,
            "variant": spec.variant,
        }
        extending = self.sweep.settings.eval_tasks is not None and self.record_path(run).is_file()
        earlier = self.read_record(run) if extending else None
        if earlier is not None and not self.same_protocol(run, earlier, protocol):
            return False
        parts = [(out, self.eval_command(run, checkpoint, out, extra)) for out, extra in self.eval_parts(run)]
        workers = max(1, min(self.sweep.settings.eval_workers, len(parts)))
        log = self.log_path(run.config, run.suite, run.seed, "eval")

        def part_log(out: Path) -> Path:
            return log if workers == 1 else log.with_name(f"{log.stem}.{out.name}.log")

        with ThreadPoolExecutor(max_workers=workers) as pool:
            finished = list(pool.map(lambda part: self.evaluate_part(run, part[1], part[0], part_log(part[0])), parts))
        if not all(finished):
            return False
        tasks, walls, machines = self.part_results([out for out, _ in parts])
        unsettled: dict | None = {task: [] for task in tasks}  # task -> its unsettled episodes' indices
        for out, _ in parts:
            unsettled.update(unsettled_episodes(out / EVAL_INFO_FILE))
        unsettled_count = sum(map(len, unsettled.values()))
        commands = [command for _, command in parts]
        eval_tasks = self.sweep.settings.eval_tasks
        if earlier is not None:  # the earlier record's other tasks, with their commands and wall time
            new = [i for i, (task, _) in enumerate(walls) if task not in earlier["tasks"]]
            new_tasks = sorted(set(tasks) - set(earlier["tasks"]), key=int)
            unsettled_count = (earlier.get("shift_unsettled") or 0) + sum(len(unsettled[t]) for t in new_tasks)
            before = recorded_unsettled(earlier)  # None: an earlier record that kept the count alone
            unsettled = None if before is None else dict(
                sorted({**before, **{t: unsettled[t] for t in new_tasks}}.items(), key=lambda kv: int(kv[0])))
            earlier_commands = earlier.get("commands", {}).get("eval") or []
            if earlier_commands and isinstance(earlier_commands[0], str):
                earlier_commands = [earlier_commands]  # one part: the command itself
            commands = [*earlier_commands, *(commands[i] for i in new)]
            walls = [("", earlier.get("eval_wall_s") or 0.0), *(walls[i] for i in new)]
            tasks = dict(sorted({**earlier["tasks"], **tasks}.items(), key=lambda kv: int(kv[0])))
            eval_tasks = sorted(int(t) for t in tasks)
            machines = {**(earlier.get("part_machines") or {}), **machines}
        successes, episodes = episode_totals(tasks.values())
        record = {
            "config": run.config,
            "group": spec.group,
            "label": spec.label,
            "compare_to": spec.compare_to,
            "pool_with": spec.pool_with,
            "pool_sets": spec.pool_sets,
            "branch": spec.branch,
            "corruption": spec.corruption,
            "eval_overrides": spec.eval_overrides,
            "init_states": spec.init_states,
            "object_shift": spec.object_shift,  # with the episodes whose shifted bodies did not settle (unsettled)
            "shift_unsettled": unsettled_count if spec.object_shift else None,
            # per task, their indices in its successes (the report's analysis without them); None: not known
            "shift_unsettled_episodes": unsettled if spec.object_shift else None,
            "variant": spec.variant,
            "eval_seed": protocol["eval_seed"],
            "checkpoint_from": spec.checkpoint_from,
            "suite": run.suite,
            "seed": run.seed,
            "steps": trained["steps"],
            "parameters": trained["parameters"],
            "eval_tasks": eval_tasks,  # the tasks evaluated one part each; None: the whole suite in one part
            "tasks": tasks,
            "successes": successes,
            "episodes": episodes,
            "success_rate": percent(successes, episodes),
            "n_episodes_per_task": protocol["n_episodes_per_task"],
            "episode_length": protocol["episode_length"],
            "train_wall_s": trained["train_wall_s"],
            # summed over the parts: with several workers, more than the elapsed time
            "eval_wall_s": round(sum(wall for _, wall in walls), 1),
            "eval_workers": workers,
            "checkpoint": trained["checkpoint"],
            # the weights evaluated: a training redone in place leaves the path, not this (report.paired.same_model)
            "model_sha256": protocol["model_sha256"],
            "commands": {"train": trained["command"], "eval": commands[0] if len(commands) == 1 else commands},
            "versions": run_versions(),
            # per part (its first task), the machine it ran on, where its part file names one
            "part_machines": dict(sorted(machines.items(), key=lambda kv: int(kv[0]))),
            "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        atomic_write_json(self.record_path(run), record)
        return True

    def same_protocol(self, run: Run, earlier: dict, protocol: dict) -> bool:
        """Whether an earlier record's tasks were measured as this call's will be (model, episodes, step cap, seed,
        settings), so that both pool in one record; if not, says which field differs and what to do."""
        for key, value in protocol.items():
            if key in earlier and earlier[key] != value:
                print(f"predvla sweep: {self.record_path(run)} holds tasks {', '.join(earlier['tasks'])} with {key} = "
                      f"{earlier[key]!r}; this call would evaluate tasks {self.sweep.settings.eval_tasks} with "
                      f"{key} = {value!r}, which do not pool. Run them with the record's protocol, or move the record "
                      "aside to record this call's tasks alone", file=sys.stderr)
                return False
        return True

    def part_results(
        self, outs: list[Path]
    ) -> tuple[dict[str, dict[str, int]], list[tuple[str, float]], dict[str, str]]:
        """Per-task successes of the parts' `eval_info.json`, sorted by task id; (first task, wall time) per part;
        and per part's first task the machine its part file names (`part_machine`; parts written before part files
        named one are left out)."""
        tasks, walls, machines = {}, [], {}
        for out in outs:
            try:
                part = parse_eval_info(out / EVAL_INFO_FILE)
            except EvalInfoError as err:
                raise SweepError(str(err)) from err
            tasks.update(part)
            wall_file = out / EVAL_WALL_FILE
            info = json.loads(wall_file.read_text()) if wall_file.is_file() else {}
            first = next(iter(part))
            walls.append((first, info.get("eval_wall_s", 0.0)))
            if info.get("machine"):
                machines[first] = info["machine"]
        return dict(sorted(tasks.items(), key=lambda kv: int(kv[0]))), walls, machines
