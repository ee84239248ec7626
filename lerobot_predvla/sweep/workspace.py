"""A sweep and its RUNS_DIR: the paths of its runs, the programs it runs and how it runs them. The runner's stages
(data, training, evaluation) build on it."""

import signal
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from lerobot_predvla.lerobot_commands import ACCELERATE, LEROBOT_EVAL, LEROBOT_TRAIN, TORCHRUN
from lerobot_predvla.sweep.layout import (
    TRAIN_DONE_FILE,
    eval_run_dir,
    record_path,
    run_log_path,
    train_run_dir,
)
from lerobot_predvla.sweep.logs import compact_log
from lerobot_predvla.sweep.spec import Run, Sweep

Executor = Callable[[list[str], Path], int]  # (command, log file) -> exit code


# What a signal that ends a stage usually means here, for the failure message.
SIGNAL_CAUSES = {
    signal.SIGILL: "an instruction this processor lacks, e.g. OPENBLAS_CORETYPE naming kernels it cannot run",
    signal.SIGKILL: "killed from outside, often by the kernel when memory runs out",
    signal.SIGSEGV: "a crash in native code",
}


def describe_exit(code: int) -> str:
    """A process's exit code in words: "exit 2", or for a negative code the signal that ended it and its usual
    cause ("killed by SIGILL: an instruction this processor lacks, ...")."""
    if code >= 0:
        return f"exit {code}"
    try:
        sig = signal.Signals(-code)
    except ValueError:
        return f"exit {code}"
    cause = SIGNAL_CAUSES.get(sig)
    return f"killed by {sig.name}" + (f": {cause}" if cause else "")


class SweepStopped(Exception):
    """`stop_at` passed before a stage (a data stage, a training, an evaluation part) started: nothing of it ran."""


def subprocess_executor(command: list[str], log: Path) -> int:
    """Run a command with stdout and stderr appended to `log`, then keep only its progress bars' last states."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a") as out:
        out.write(f"$ {' '.join(command)}\n")
        out.flush()
        code = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, check=False).returncode
    compact_log(log)
    return code


@dataclass
class Workspace:
    """The runs of a sweep under `runs_dir`; `execute` is injectable (tests use a fake)."""

    sweep: Sweep
    runs_dir: Path
    execute: Executor = subprocess_executor
    lerobot_train: str = LEROBOT_TRAIN
    lerobot_eval: str = LEROBOT_EVAL
    accelerate: str = ACCELERATE
    torchrun: str = TORCHRUN
    # No stage starts after this time (`predvla sweep --stop-at`); those running finish, a later call resumes the rest.
    stop_at: datetime | None = None

    def check_stop_at(self, stage: str) -> None:
        """Raise `SweepStopped` instead of starting `stage` once `stop_at` has passed."""
        if self.stop_at is not None and datetime.now(self.stop_at.tzinfo) >= self.stop_at:
            raise SweepStopped(f"{stage} not started: --stop-at {self.stop_at.isoformat(timespec='minutes')} passed")

    def train_dir(self, config: str, suite: str, seed: int) -> Path:
        return train_run_dir(self.runs_dir, config, suite, seed)

    def eval_dir(self, run: Run) -> Path:
        return eval_run_dir(self.runs_dir, run.config, run.suite, run.seed)

    def record_path(self, run: Run) -> Path:
        return record_path(self.runs_dir, run.config, run.suite, run.seed)

    def log_path(self, name: str, suite: str, seed: int, stage: str) -> Path:
        return run_log_path(self.runs_dir, name, suite, seed, stage)

    def sweep_path(self, value: str) -> Path:
        """A path of the sweep file, relative to the file's folder unless absolute."""
        path = Path(value)
        return path if path.is_absolute() else (self.sweep.base_dir / path).resolve()

    def train_root(self, suite: str) -> Path | None:
        """The copy of `suite`'s dataset without camera frames that training reads, when the sweep names one."""
        train_root = self.sweep.settings.datasets[suite].get("train_root")
        return self.sweep_path(train_root) if train_root else None

    def trained_checkpoint(self, trained: dict) -> Path:
        """The checkpoint of a finished training (`TRAIN_DONE_FILE`), kept relative to RUNS_DIR so that a sweep
        directory moved to another machine, or pointed at a committed checkpoint, still finds it."""
        return (self.runs_dir / trained["checkpoint"]).resolve()

    def evaluable_checkpoint(self, trained: dict, out: Path) -> Path | None:
        """The checkpoint a finished training (`out`'s `TRAIN_DONE_FILE`) names, checked before its evaluations;
        None, with what to do on stderr, when it is gone: one left out of a copied or cloned RUNS_DIR must not turn
        into an evaluation error per task."""
        checkpoint = self.trained_checkpoint(trained)
        if (checkpoint / "model.safetensors").is_file():
            return checkpoint
        done = out / TRAIN_DONE_FILE
        print(
            f"predvla sweep: {done} names the checkpoint {checkpoint}, which has no model.safetensors. Restore "
            f"that checkpoint, or remove {done} to train it again: evaluations already recorded from the lost "
            "model keep their records (move those aside to evaluate the new model in their place)",
            file=sys.stderr,
        )
        return None
