"""`predvla sweep --status`: where each run of a sweep stands, read from RUNS_DIR without running anything: its
training (finished, at which saved step, or not started), its evaluation parts finished and their successes so far,
and the time its remaining parts should take at the median wall time of its finished ones."""

import math
import statistics
from dataclasses import dataclass

from lerobot_predvla.sweep.eval_info import EVAL_INFO_FILE
from lerobot_predvla.sweep.layout import TRAIN_DONE_FILE
from lerobot_predvla.sweep.runner import Runner
from lerobot_predvla.utils.checkpoints import checkpoint_step, last_pretrained
from lerobot_predvla.utils.statistics import episode_totals


@dataclass
class RunStatus:
    key: str
    training: str  # "done", "step N of M" (its last saved checkpoint) or "not started"
    parts_done: int  # evaluation parts with their eval_info.json (one per task with eval.tasks, else one)
    parts: int
    successes: int  # over the finished parts (or the run's record)
    episodes: int
    recorded: bool  # the run's record holds every task asked for
    part_walls_s: list[float]  # the finished parts' wall times (those the sweep timed)

    def seconds_left(self, workers: int) -> float | None:
        """The remaining parts at the median wall time of the finished ones, `workers` at once; None: none timed."""
        if self.parts_done == self.parts:
            return 0.0
        walls = [w for w in self.part_walls_s if w > 0]
        if not walls:
            return None
        return statistics.median(walls) * math.ceil((self.parts - self.parts_done) / workers)


def training_state(runner: Runner, config: str, suite: str, seed: int) -> str:
    out = runner.train_dir(config, suite, seed)
    if (out / TRAIN_DONE_FILE).is_file():
        return "done"
    last = last_pretrained(out)
    if not last.exists():
        return "not started"
    steps = runner.sweep.steps_of(runner.sweep.configs[config])
    return f"step {checkpoint_step(last.resolve()):,} of {steps:,}"


def sweep_status(runner: Runner, configs: list[str] | None, shard: tuple[int, int]) -> list[RunStatus]:
    """One row per run of this shard, in the order `run` takes them."""
    rows = []
    for (trained, suite, seed), unit_runs in runner.shard_units(configs, shard):
        training = training_state(runner, trained, suite, seed)
        for run in unit_runs:
            outs = [out for out, _ in runner.eval_parts(run)]
            done = [out for out in outs if (out / EVAL_INFO_FILE).is_file()]
            tasks, walls, _ = runner.part_results(done) if done else ({}, [], {})
            recorded = runner.is_recorded(run)
            if recorded and not done:  # a record whose part folders are elsewhere (a copied RUNS_DIR)
                tasks, done = runner.read_record(run)["tasks"], outs
            rows.append(RunStatus(run.key, training, len(done), len(outs), *episode_totals(tasks.values()),
                                  recorded, [wall for _, wall in walls]))
    return rows


def hours(seconds: float | None) -> str:
    return "?" if seconds is None else f"{seconds / 3600:.1f} h"


def format_status(rows: list[RunStatus], workers: int) -> str:
    """A plain-text table of the rows and a last line with the totals."""
    header = ("run", "training", "evaluation parts", "successes", "left (est.)")
    table = [header] + [
        (r.key, r.training, f"{r.parts_done}/{r.parts}" + (" recorded" if r.recorded else ""),
         f"{r.successes}/{r.episodes}" if r.episodes else "-", hours(r.seconds_left(workers)))
        for r in rows
    ]
    widths = [max(len(line[i]) for line in table) for i in range(len(header))]
    lines = ["  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)).rstrip() for line in table]
    left = [r.seconds_left(workers) for r in rows]
    unknown = sum(s is None for s in left)
    known = f"about {hours(sum(s for s in left if s is not None))}" if unknown < len(rows) else "unknown"
    untimed = f" (not counting {unknown} {'run' if unknown == 1 else 'runs'} with no timed part yet)" if unknown else ""
    lines.append(f"{sum(r.recorded for r in rows)} of {len(rows)} runs recorded; evaluation left {known}{untimed} "
                 f"at {workers} {'part' if workers == 1 else 'parts'} at once; trainings not counted")
    return "\n".join(lines)
