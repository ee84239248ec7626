"""Experiment runner: `lerobot-train` then `lerobot-eval` for configurations x suites x seeds.

A sweep file (YAML or JSON) lists configurations; every (configuration, suite, seed) is one run whose result is
a JSON record `RUNS_DIR/records/<config>/<suite>/seed<k>.json`. Runs whose record holds the tasks asked for are
skipped (a call for other tasks adds them to the record), a training killed midway resumes from its last
checkpoint (`lerobot-train --resume=true`), an evaluation killed midway is redone. Inference-time variants
(`checkpoint_from: <config>`) evaluate another configuration's checkpoints with extra `lerobot-eval` arguments and
train nothing themselves.

A configuration with `lr_sweep` first chooses its learning rate on held-out demonstrations (`lr_selection.py`):
one shorter candidate training per rate, then its own training at the chosen rate.

Scaling out: `--shard i/n` runs every n-th training unit (a checkpoint with all evaluations that use it), so n
processes or hosts sharing RUNS_DIR split a sweep without overlap; `accelerate_processes > 1` trains each run
with `accelerate launch --multi_gpu` (LeRobot's multi-GPU path).

Modules by job: `spec` (the sweep file), `layout` (where RUNS_DIR holds what), `workspace` (paths and execution),
`data`, `training` (with learning-rate selection and publishing) and `evaluation` (the stages), `runner` (plan,
shards, running); every `lerobot-train` and `lerobot-eval` command line comes from `lerobot_predvla.lerobot_commands`.
"""

from lerobot_predvla.sweep.layout import TRAIN_DONE_FILE
from lerobot_predvla.sweep.runner import Runner
from lerobot_predvla.sweep.spec import (
    PAPER_BATCH_SIZE,
    PAPER_TRAIN_STEPS,
    ConfigSpec,
    Run,
    Sweep,
    SweepError,
    parse_shard,
)
from lerobot_predvla.sweep.workspace import SweepStopped, subprocess_executor

__all__ = [
    "PAPER_BATCH_SIZE",
    "PAPER_TRAIN_STEPS",
    "TRAIN_DONE_FILE",
    "ConfigSpec",
    "Run",
    "Runner",
    "Sweep",
    "SweepError",
    "SweepStopped",
    "parse_shard",
    "subprocess_executor",
]
