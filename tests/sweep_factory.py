"""A sweep file and fake lerobot-train / lerobot-eval executors for the sweep tests."""

import argparse
import json
from datetime import UTC, datetime, timedelta
from pathlib import Path

import torch
import yaml
from safetensors.torch import save_file

from lerobot_predvla.frontend.artefact import METADATA_FILE


def sweep_file(tmp_path: Path, **changes) -> Path:
    (tmp_path / "L3.json").write_text(json.dumps({"type": "predvla", "er_iterations": 0, "tau": [1, 1, 1, 1]}))
    spec = {
        "seeds": [0, 1],
        "suites": ["libero_object", "libero_spatial"],
        "datasets": {s: {"repo_id": f"local/{s}", "root": f"data/{s}"} for s in ("libero_object", "libero_spatial")},
        "train": {"device": "cpu"},
        "eval": {"device": "cpu"},
        "configs": [
            {"name": "predvla", "group": "main", "suite_overrides": {"libero_10": {"sequence_length": 500}}},
            {"name": "A6", "group": "ablation", "checkpoint_from": "predvla", "compare_to": "predvla",
             "eval_overrides": {"er_iterations": 0}, "label": "- Online ER"},
            {"name": "L3", "group": "ladder", "policy": "L3.json", "suites": ["libero_object"]},
        ],
        **changes,
    }
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def cli_flags(**given) -> argparse.Namespace:
    """`predvla sweep`'s protocol flags as parsed: None (not given) except `given`."""
    names = ("seeds", "suites", "steps", "n_episodes", "episode_length", "device", "accelerate_processes",
             "eval_workers", "eval_tasks")
    return argparse.Namespace(**{**dict.fromkeys(names), **given})


def differing_flags(command: list[str], reference: list[str]) -> set[str]:
    """The flag names (before `=`) of the arguments that only one of two commands has."""
    return {a.split("=")[0] for a in set(command) ^ set(reference)}


def arg(command: list[str], name: str) -> str | None:
    return next((c.split("=", 1)[1] for c in command if c.startswith(f"--{name}=")), None)


class FakeLeRobot:
    """Stands in for lerobot-train / lerobot-eval: writes what they would write, records every command."""

    def __init__(self, kill_training: int = 0):
        self.commands: list[list[str]] = []
        self.kill_training = kill_training  # the first n trainings die after their first checkpoint

    def __call__(self, command: list[str], log: Path) -> int:
        self.commands.append(command)
        if any(c.endswith("lerobot-eval") for c in command):
            out = Path(arg(command, "output_dir"))
            out.mkdir(parents=True)
            seed, n = int(arg(command, "seed")), int(arg(command, "eval.n_episodes"))
            per_task = [{"task_group": arg(command, "env.task"), "task_id": t,
                         "metrics": {"successes": [i < n - t - seed for i in range(n)], "sum_rewards": [0] * n}}
                        for t in json.loads(arg(command, "env.task_ids") or "[0, 1, 2]")]
            (out / "eval_info.json").write_text(json.dumps({"per_task": per_task, "overall": {}}))
            return 0
        if arg(command, "config_path"):  # resume
            out = Path(arg(command, "config_path")).parents[3]
        else:
            out = Path(arg(command, "output_dir"))
            assert not out.exists(), "lerobot-train refuses an existing output_dir without --resume"
        ckpt = out / "checkpoints" / "000002" / "pretrained_model"
        ckpt.mkdir(parents=True, exist_ok=True)
        (ckpt / "train_config.json").write_text("{}")
        if not (out / "checkpoints" / "last").exists():
            (out / "checkpoints" / "last").symlink_to("000002")
        if self.kill_training:
            self.kill_training -= 1
            return -9
        save_file({"w": torch.zeros(3, 4), "b": torch.zeros(5)}, str(ckpt / "model.safetensors"))
        return 0

    def count(self, program: str) -> int:
        return sum(any(c.endswith(program) for c in cmd) for cmd in self.commands)


class ClockRunsOut(FakeLeRobot):
    """A FakeLeRobot after whose first lerobot-eval call the runner's `--stop-at` time has passed."""

    def __init__(self, runner, **kwargs):
        super().__init__(**kwargs)
        self.runner = runner

    def __call__(self, command: list[str], log: Path) -> int:
        code = super().__call__(command, log)
        if any(c.endswith("lerobot-eval") for c in command):
            self.runner.stop_at = datetime.now(UTC) - timedelta(minutes=1)
        return code


class FakeData(FakeLeRobot):
    """Also stands in for `predvla demos`, `fit-frontend` and `convert`, writing the files they would write."""

    def __call__(self, command: list[str], log: Path) -> int:
        if "lerobot_predvla.cli.main" not in command:
            return super().__call__(command, log)
        self.commands.append(command)
        stage = command[command.index("lerobot_predvla.cli.main") + 1]
        value = dict(zip(command, command[1:], strict=False))
        if stage == "demos":
            from lerobot_predvla.sims.libero.env import task_spec
            from lerobot_predvla.sims.libero.hdf5_layout import task_file

            for task in value["--tasks"].split(","):
                path = task_file(Path(value["--out"]), task_spec(value["--suite"], int(task)))
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text("demos")
        elif stage == "fit-frontend":
            Path(value["--out"]).mkdir(parents=True)
            (Path(value["--out"]) / METADATA_FILE).write_text("{}")
        else:
            (Path(value["--out"]) / "meta").mkdir(parents=True)
            (Path(value["--out"]) / "meta" / "info.json").write_text("{}")
        return 0
