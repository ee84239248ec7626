"""The training stages of a sweep: `lerobot-train` (or its resume) of each checkpoint, the learning rate chosen on
held-out demonstrations first for a configuration with `lr_sweep` (`lr_selection.py`), and the final model published
for a sweep with `train.publish`."""

import filecmp
import json
import math
import os
import shutil
import sys
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

from lerobot_predvla import lerobot_commands
from lerobot_predvla.sweep.data import DataStages
from lerobot_predvla.sweep.layout import TRAIN_DONE_FILE
from lerobot_predvla.sweep.lr_selection import (
    CRITERION,
    PENDING_LR,
    candidate_name,
    candidate_path,
    choose,
    divergence,
    heldout_episodes,
    heldout_losses,
    selection_path,
)
from lerobot_predvla.sweep.spec import ConfigSpec, SweepError
from lerobot_predvla.sweep.workspace import describe_exit
from lerobot_predvla.utils.checkpoints import last_pretrained, prune_checkpoints
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.parameters import count_parameters
from lerobot_predvla.utils.versions import machine


class Training(DataStages):
    """Trains (or resumes, or reuses) the checkpoints of a sweep."""

    def launcher(self) -> list[str]:
        """The program words of every `lerobot-train` of the sweep (`accelerate_processes` processes)."""
        s = self.sweep.settings
        return lerobot_commands.launcher(
            s.accelerate_processes, s.train_device, self.lerobot_train, self.accelerate, self.torchrun
        )

    def train_command(self, spec: ConfigSpec, suite: str, seed: int) -> list[str]:
        s = self.sweep.settings
        spec = self.at_selected_lr(spec, suite)
        dataset = s.datasets[suite]
        procs = s.accelerate_processes
        if s.batch_size % procs:
            raise SweepError(f"batch_size {s.batch_size} is not divisible by accelerate_processes {procs}.")
        return lerobot_commands.train_command(
            program=self.launcher(),
            policy=spec.policy_args(self.sweep.base_dir, suite),
            dataset_repo_id=dataset["repo_id"],
            dataset_root=(self.train_root(suite) or self.sweep_path(dataset["root"])) if dataset.get("root") else None,
            output_dir=self.train_dir(spec.name, suite, seed),
            job_name=f"{spec.name}_{suite}_seed{seed}",
            seed=seed,
            steps=self.sweep.steps_of(spec),
            batch_size=s.batch_size // procs,  # per process: the effective batch stays batch_size
            save_freq=s.save_freq,
            device=s.train_device,
            extra=[*s.train_args, *spec.train_args],
        )

    def resume_command(self, train_dir: Path, suite: str) -> list[str]:
        """Resume from the last checkpoint, with its own train_config.json; a sweep that names a `train_root`
        points the resumed training at it (LeRobot lets command-line flags override a resumed config): the same
        samples without camera frames, for trainings started before the copy existed."""
        config = last_pretrained(train_dir) / "train_config.json"
        train_root = self.train_root(suite)
        return [
            *self.launcher(),
            *lerobot_commands.resume_args(config),
            *([f"--dataset.root={train_root}"] if train_root else []),
        ]

    def pending_train_command(self, spec: ConfigSpec, suite: str, seed: int) -> list[str]:
        """A training's resume command when it has a checkpoint, else its command from the start."""
        out = self.train_dir(spec.name, suite, seed)
        if (last_pretrained(out) / "train_config.json").is_file():
            return self.resume_command(out, suite)
        return self.train_command(spec, suite, seed)

    def pending_lr_commands(self, spec: ConfigSpec, suite: str) -> list[list[str]]:
        """The candidate trainings a learning-rate selection still needs (none once it has chosen)."""
        sweep = spec.lr_sweep
        if sweep is None or selection_path(self.runs_dir, spec.name, suite).is_file():
            return []
        candidates = [
            self.candidate_spec(spec, rate)
            for rate in sweep.rates
            if not candidate_path(self.runs_dir, spec.name, suite, rate).is_file()
        ]
        return [
            self.pending_train_command(c, suite, sweep.seed)
            for c in candidates
            if not (self.train_dir(c.name, suite, sweep.seed) / TRAIN_DONE_FILE).is_file()
        ]

    def train(self, spec: ConfigSpec, suite: str, seed: int, publish: bool = True) -> dict | None:
        """Train (or resume, or reuse) one checkpoint; None when lerobot-train (or its `train.publish`) failed.
        `publish=False`: never publish it (a learning-rate candidate)."""
        out = self.train_dir(spec.name, suite, seed)
        done = out / TRAIN_DONE_FILE
        if done.is_file():
            return json.loads(done.read_text())
        if not self.make_data(suite):  # the dataset is needed only to train: evaluations never read it
            return None
        if spec.lr_sweep is not None and self.select_lr(spec, suite) is None:
            return None
        last = last_pretrained(out)
        if (last / "train_config.json").is_file():
            command, resumed = self.resume_command(out, suite), True
        else:
            shutil.rmtree(out, ignore_errors=True)  # started but no checkpoint yet: lerobot-train needs a new dir
            command, resumed = self.train_command(spec, suite, seed), False
        self.check_stop_at(f"training {spec.name}/{suite}/seed{seed}")
        start = time.monotonic()
        code = self.execute(command, self.log_path(spec.name, suite, seed, "train"))
        if code != 0 or not (last / "model.safetensors").is_file():
            print(
                f"predvla sweep: training {spec.name}/{suite}/seed{seed} failed ({describe_exit(code)}); see "
                f"{self.log_path(spec.name, suite, seed, 'train')}",
                file=sys.stderr,
            )
            return None
        train_wall = round(time.monotonic() - start, 1)
        keep_every = self.sweep.settings.keep_every
        pruned = prune_checkpoints(out, keep_every) if keep_every else []
        published = self.publish_model(spec, suite, seed, last) if publish and self.sweep.settings.publish else None
        if published is False:
            return None
        result = {
            "checkpoint": os.path.relpath((published or last).resolve(), self.runs_dir.resolve()),
            "steps": self.sweep.steps_of(spec),
            "parameters": count_parameters(last / "model.safetensors"),
            "train_wall_s": train_wall,  # this call only: a resumed training's earlier calls are in its log
            "machine": machine(),
            "resumed": resumed,
            "command": command,
            "checkpoints_pruned": len(pruned),
        }
        if published:
            result["trained_checkpoint"] = os.path.relpath(last.resolve(), self.runs_dir.resolve())
        atomic_write_json(done, result)
        return result

    def publish_dir(self, spec: ConfigSpec, suite: str, seed: int) -> Path:
        return self.sweep_path(self.sweep.settings.publish.format(config=spec.name, suite=suite, seed=seed))

    @staticmethod
    def publish_command(dest: Path, last: Path) -> list[str]:
        return [*lerobot_commands.PREDVLA, "push", str(last), os.path.relpath(dest), "--out", str(dest)]

    def publish_model(self, spec: ConfigSpec, suite: str, seed: int, last: Path) -> Path | bool:
        """`train.publish`: the final model of a training, as `predvla push --out` writes it, in its folder; False
        when that failed. A folder already there (a sweep stopped between the copy and the training record) is
        kept if it holds this training's weights, and refused otherwise (the run fails; nothing is overwritten)."""
        dest = self.publish_dir(spec, suite, seed)
        if dest.exists():
            if (dest / "model.safetensors").is_file() and filecmp.cmp(
                dest / "model.safetensors", last / "model.safetensors", shallow=False
            ):
                return dest
            print(
                f"predvla sweep: train.publish: {dest} exists and does not hold the weights of {last}; move it "
                "away or change train.publish.",
                file=sys.stderr,
            )
            return False
        command = self.publish_command(dest, last)
        log = self.log_path(spec.name, suite, seed, "publish")
        code = self.execute(command, log)
        if code != 0 or not (dest / "model.safetensors").is_file():
            print(
                f"predvla sweep: publishing {spec.name}/{suite}/seed{seed} to {dest} failed "
                f"({describe_exit(code)}); see {log}",
                file=sys.stderr,
            )
            return False
        return dest

    # ----- learning-rate selection ---------------------------------------------------------------------------
    def candidate_spec(self, spec: ConfigSpec, rate: float) -> ConfigSpec:
        """The candidate training of `spec` at `rate`: its sweep's steps, episodes held out, nothing to select."""
        sweep = spec.lr_sweep
        return replace(
            spec,
            name=candidate_name(spec.name, rate),
            steps=sweep.steps,
            lr_sweep=None,
            policy_overrides={**spec.policy_overrides, "optimizer_lr": float(rate)},
            train_args=[*spec.train_args, *sweep.train_args()],
        )

    def at_selected_lr(self, spec: ConfigSpec, suite: str) -> ConfigSpec:
        """`spec` with its chosen learning rate (a placeholder before the selection, for dry runs)."""
        if spec.lr_sweep is None:
            return spec
        path = selection_path(self.runs_dir, spec.name, suite)
        rate = json.loads(path.read_text())["chosen_lr"] if path.is_file() else PENDING_LR
        return replace(spec, policy_overrides={**spec.policy_overrides, "optimizer_lr": rate})

    def lr_candidate(self, spec: ConfigSpec, suite: str, rate: float) -> dict | None:
        """Train (or reuse) one candidate and read its held-out loss; None when its training failed other than by
        diverging (a re-run retries it)."""
        path = candidate_path(self.runs_dir, spec.name, suite, rate)
        if path.is_file():
            return json.loads(path.read_text())
        sweep, candidate = spec.lr_sweep, self.candidate_spec(spec, rate)
        log = self.log_path(candidate.name, suite, sweep.seed, "train")
        trained = self.train(candidate, suite, sweep.seed, publish=False)
        if trained is None:
            diverged = divergence(log)
            if diverged is None:
                return None
            result = {"lr": float(rate), "heldout_nll": None, "diverged": diverged}
        else:
            curve = heldout_losses(log)
            if sweep.steps not in curve:
                raise SweepError(
                    f"{log}: no held-out loss at step {sweep.steps} (`step {sweep.steps}: eval_loss=`); "
                    f"delete {self.train_dir(candidate.name, suite, sweep.seed)} to train the "
                    "candidate again."
                )
            final = curve[sweep.steps]
            result = {
                "lr": float(rate),
                "heldout_nll": final if math.isfinite(final) else None,
                "heldout_curve": {str(step): loss for step, loss in sorted(curve.items())},
                "steps": trained["steps"],
                "train_wall_s": trained["train_wall_s"],
                "checkpoint": trained["checkpoint"],
                "command": trained["command"],
            }
        atomic_write_json(path, result)
        return result

    def select_lr(self, spec: ConfigSpec, suite: str) -> float | None:
        """The learning rate of `spec` on `suite` chosen on held-out demonstrations (`lr_selection.py`), selecting
        it first if needed; None when a candidate's training failed."""
        path = selection_path(self.runs_dir, spec.name, suite)
        if path.is_file():
            return json.loads(path.read_text())["chosen_lr"]
        sweep = spec.lr_sweep
        candidates = {}
        for rate in sweep.rates:
            result = self.lr_candidate(spec, suite, rate)
            if result is None:
                return None
            candidates[float(rate)] = result
        try:
            chosen = choose({rate: result["heldout_nll"] for rate, result in candidates.items()})
        except ValueError as err:
            raise SweepError(f"configuration {spec.name} on {suite}: {err}") from err
        dataset = self.sweep.settings.datasets[suite]
        atomic_write_json(
            path,
            {
                "config": spec.name,
                "suite": suite,
                "criterion": CRITERION,
                "rates": [float(r) for r in sweep.rates],
                "steps": sweep.steps,
                "eval_split": sweep.eval_split,
                "seed": sweep.seed,
                "heldout_episodes": heldout_episodes(
                    dataset["repo_id"], self.sweep_path(dataset["root"]), sweep.eval_split
                ),
                "heldout_nll": {f"{rate:g}": result["heldout_nll"] for rate, result in candidates.items()},
                "chosen_lr": chosen,
                "finished": datetime.now(UTC).isoformat(timespec="seconds"),
            },
        )
        print(
            f"predvla sweep: {spec.name} on {suite}: optimizer_lr {chosen:g} chosen on held-out demonstrations; "
            f"see {path}",
            file=sys.stderr,
        )
        return chosen
