"""Where `predvla sweep` writes under RUNS_DIR, read back by `predvla report`.

- `plan.json`: every planned run and each configuration's description;
- `records/<config>/<suite>/seed<k>.json`: one record per finished run;
- `train/<config>/<suite>/seed<k>/`: a training's `lerobot-train` output, `TRAIN_DONE_FILE` once it finished;
- `eval/<config>/<suite>/seed<k>/`: its evaluation's `eval_info.json`, or one per task part;
- `data/<suite>.json`: the command and wall time of each data stage;
- `logs/<config>/<suite>/seed<k>.<stage>.log`: every stage's output.
"""

from pathlib import Path

from lerobot_predvla.utils.checkpoints import TRAIN_DONE_FILE  # noqa: F401  (part of the runs directory layout)

PLAN_FILE = "plan.json"
RECORDS_DIR = "records"
TRAIN_DIR = "train"
DATA_DIR = "data"
EVAL_WALL_FILE = "predvla_sweep_eval.json"  # wall time of one evaluation part, beside its eval_info.json


def train_run_dir(runs_dir: Path, config: str, suite: str, seed: int) -> Path:
    """Where a training writes its checkpoints (`lerobot-train --output_dir`)."""
    return Path(runs_dir) / TRAIN_DIR / config / suite / f"seed{seed}"


def eval_run_dir(runs_dir: Path, config: str, suite: str, seed: int) -> Path:
    """Where a run's evaluation writes: its eval_info.json, or one task part per subfolder."""
    return Path(runs_dir) / "eval" / config / suite / f"seed{seed}"


def record_path(runs_dir: Path, config: str, suite: str, seed: int) -> Path:
    return Path(runs_dir) / RECORDS_DIR / config / suite / f"seed{seed}.json"


def run_log_path(runs_dir: Path, name: str, suite: str, seed: int, stage: str) -> Path:
    """Where a stage (train, eval, publish, or a data stage under name "data") of a run writes its log."""
    return Path(runs_dir) / "logs" / name / suite / f"seed{seed}.{stage}.log"


def data_stages_path(runs_dir: Path, suite: str) -> Path:
    """The command and wall time of each data stage that made `suite`'s datasets."""
    return Path(runs_dir) / DATA_DIR / f"{suite}.json"
