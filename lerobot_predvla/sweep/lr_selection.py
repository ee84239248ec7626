"""Learning-rate selection on held-out demonstrations, never on the evaluation's init states.

The paper's baselines train "at the best of a four-point learning-rate sweep" (Section 4.5) without saying how
"best" was judged. A sweep configuration with `lr_sweep` judges it on demonstrations the candidate did not train
on: one shorter `lerobot-train` run per rate with `--dataset.eval_split=f --eval_steps=n`. LeRobot 0.6.1 then holds
out the last ceil(f x episodes) episodes of every task (`lerobot.datasets.factory.make_train_eval_datasets`),
trains on the others only, and every n steps logs the policy's own loss on the held-out episodes
(`step N: eval_loss=X`; for B1 and B2 the Gaussian-mixture head's action NLL). The rate with the lowest held-out
loss at the candidate's last step is chosen, and the configuration's own training then uses all episodes at that
rate. Each candidate's result and the selection are JSON files under RUNS_DIR/lr_sweep/, written once, so a
re-run skips what is done (the candidates' trainings resume like any other).
"""

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

from lerobot_predvla.policies.common.training_guard import NONFINITE_STOP

LR_SWEEP_DIR = "lr_sweep"
CANDIDATE_PREFIX = "lr"  # lr0.0003: a candidate's run-name suffix and result file stem
CRITERION = ("lowest policy loss (action NLL) on held-out demonstrations at the candidate's last step, "
             "LeRobot's eval_loss with --dataset.eval_split")
# What a dry run prints for the learning rate of a training whose selection has not run yet.
PENDING_LR = "<lowest held-out NLL of lr_sweep>"
_EVAL_LOSS = re.compile(r"step (\d+): eval_loss=(\S+)")  # lerobot_train.py: f"step {step}: eval_loss={loss:.4f}"


@dataclass
class LRSweep:
    """A configuration's learning-rate sweep (`lr_sweep:` in a sweep file).

    Args:
        rates: Candidate values of `--policy.optimizer_lr`.
        steps: Training steps of each candidate (may be fewer than the configuration's own).
        eval_split: Fraction of each task's episodes held out (`--dataset.eval_split`; the last ones of each task).
        eval_every: Held-out loss every n steps (`--eval_steps`), kept as a curve; it must divide `steps`, whose
            value decides. Default: once, at the last step.
        seed: Training seed of the candidates; one selection serves every seed of the configuration.
    """

    rates: list[float]
    steps: int
    eval_split: float = 0.1
    eval_every: int | None = None
    seed: int = 0

    def problems(self) -> list[str]:
        """What is wrong with the values, as phrases naming the key; empty when valid."""
        found = []
        if not self.rates or any(not float(r) > 0 for r in self.rates):
            found.append(f"rates must be a non-empty list of positive learning rates, got {self.rates!r}")
        elif len({candidate_label(r) for r in self.rates}) != len(self.rates):
            found.append(f"rates must be distinct, got {self.rates!r}")
        if self.steps < 1:
            found.append(f"steps must be >= 1, got {self.steps}")
        if not 0.0 < self.eval_split < 1.0:
            found.append(f"eval_split must be in (0, 1), got {self.eval_split}")
        if self.eval_every is not None and (self.eval_every < 1 or self.steps % self.eval_every):
            found.append(f"eval_every must be >= 1 and divide steps ({self.steps}), got {self.eval_every}")
        return found

    def train_args(self) -> list[str]:
        """The `lerobot-train` arguments that hold episodes out and measure the loss on them."""
        return [f"--dataset.eval_split={self.eval_split}", f"--eval_steps={self.eval_every or self.steps}"]


def candidate_label(rate: float) -> str:
    """`lr0.0003`: the rate as it appears in run names and file names."""
    return f"{CANDIDATE_PREFIX}{float(rate):g}"


def candidate_name(config: str, rate: float) -> str:
    """The candidate's run name (`B1_lr0.0003`): its train/ and logs/ folders."""
    return f"{config}_{candidate_label(rate)}"


def selection_path(runs_dir: Path, config: str, suite: str) -> Path:
    """The selection's result: every candidate's held-out loss and the chosen rate."""
    return Path(runs_dir) / LR_SWEEP_DIR / config / f"{suite}.json"


def candidate_path(runs_dir: Path, config: str, suite: str, rate: float) -> Path:
    """One candidate's result, written when its training and held-out loss are done."""
    return Path(runs_dir) / LR_SWEEP_DIR / config / suite / f"{candidate_label(rate)}.json"


def pending_selections(runs_dir: Path) -> list[dict]:
    """Sweeps still running: for each configuration and suite whose selection is not written yet, its finished
    candidates in the selection's own keys (`config`, `suite`, `steps`, `heldout_nll` by rate as `f"{rate:g}"`)."""
    found = []
    for folder in sorted(path for path in (Path(runs_dir) / LR_SWEEP_DIR).glob("*/*") if path.is_dir()):
        config, suite = folder.parent.name, folder.name
        candidates = [json.loads(path.read_text()) for path in sorted(folder.glob(f"{CANDIDATE_PREFIX}*.json"))]
        if candidates and not selection_path(runs_dir, config, suite).is_file():
            found.append({"config": config, "suite": suite, "steps": candidates[0]["steps"],
                          "heldout_nll": {f"{c['lr']:g}": c["heldout_nll"] for c in candidates}})
    return found


def heldout_losses(log: Path) -> dict[int, float]:
    """Held-out loss per training step from a `lerobot-train` log; a step logged twice (a resumed run redid it)
    keeps its last value."""
    return {int(step): float(value) for step, value in _EVAL_LOSS.findall(log.read_text(errors="replace"))}


def divergence(log: Path) -> str | None:
    """The training guard's stop line when the run stopped on a non-finite loss or gradient (the rate diverged)."""
    if not log.is_file():
        return None
    return next((line.strip() for line in log.read_text(errors="replace").splitlines() if NONFINITE_STOP in line),
                None)


def choose(losses: dict[float, float | None]) -> float:
    """The rate with the lowest finite held-out loss (a diverged candidate has None)."""
    finite = {rate: loss for rate, loss in losses.items() if loss is not None and math.isfinite(loss)}
    if not finite:
        raise ValueError(f"no learning rate trained to a finite held-out loss: {losses}")
    return min(finite, key=finite.get)


def heldout_episodes(repo_id: str, root: Path, eval_split: float) -> dict[str, list[int]]:
    """The episodes `lerobot-train --dataset.eval_split` holds out, per task: the last ceil(eval_split x n) of each
    task's episodes in episode order (LeRobot 0.6.1's `make_train_eval_datasets`)."""
    from lerobot.datasets import LeRobotDatasetMetadata

    tasks = LeRobotDatasetMetadata(repo_id, root=root).episodes["tasks"]
    by_task: dict[str, list[int]] = {}
    for episode, names in enumerate(tasks):
        by_task.setdefault(names[0] if names else "", []).append(episode)
    return {task: episodes[len(episodes) - math.ceil(len(episodes) * eval_split):]
            for task, episodes in by_task.items()}
