"""`predvla mechanism`: error regression on a task only observations can solve (experiments/mechanism.py).

Trains a small PredVLA on the reach task for each training reading (`--reading name:field=value,...`; the bare
defaults are Table 2's readings) and evaluates each with exact open loop and every error-regression reading
(`--er name:field=value,...`), paired on the same episodes. Prints success, the visual prediction error of the chain
that acted, and where the training posteriors put the target (the fraction of episodes that follow another target's
posteriors when only one module's are swapped in), and writes the same as JSON with `--out`.
"""

import argparse
import json
import re
import time
from pathlib import Path

import torch

from lerobot_predvla.experiments.mechanism import (
    ReachTask,
    follows_swapped_posteriors,
    rollout,
    success_rate,
    task_config,
    train_policy,
)
from lerobot_predvla.policies.predvla.configuration_predvla import MODULE_NAMES
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.versions import run_versions


def reading(text: str) -> tuple[str, dict]:
    """"name:field=value,field=value" -> (name, {field: value}) with values parsed as JSON where they parse (a list
    such as complexity_weights=[0.05,0.02,1,1] keeps its commas)."""
    name, _, body = text.partition(":")
    fields = {}
    for item in filter(None, re.split(r",(?![^\[\]]*\])", body)):
        key, sep, value = item.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"{text!r}: expected name:field=value,... (got {item!r})")
        try:
            fields[key] = json.loads(value)
        except json.JSONDecodeError:
            fields[key] = value
    return name, fields


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "mechanism", help="error regression against open loop on a task only observations can solve",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--steps", type=int, default=600, help="Training steps per reading (full batches).")
    parser.add_argument("--reading", type=reading, action="append", default=None,
                        help="A training reading, name:field=value,... (repeatable; default: table2, no fields).")
    parser.add_argument("--er", type=reading, action="append", default=None,
                        help="An error-regression reading, name:field=value,... (repeatable; default: Table 2's).")
    parser.add_argument("--episodes-per-target", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0, help="Training seed (evaluation episodes: seed 1000).")
    parser.add_argument("--out", type=Path, default=None, help="Write the table as JSON here.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    torch.set_num_threads(1)
    task = ReachTask()
    readings = args.reading or [("table2", {})]
    er_readings = [("open_loop", {"er_iterations": 0}), *(args.er or [("table2_er", {})])]
    rows = []
    for name, fields in readings:
        start = time.perf_counter()
        policy, record = train_policy(task, task_config(task, **fields), args.steps, seed=args.seed)
        swapped = {m: follows_swapped_posteriors(task, policy, record, (i,)) for i, m in enumerate(MODULE_NAMES)}
        for er_name, er_fields in er_readings:
            outcome = rollout(task, policy, args.episodes_per_target, 1000, **er_fields)
            rows.append({"reading": name, "fields": fields, "inference": er_name, "inference_fields": er_fields,
                         "success": success_rate(outcome, task), "visual_error": outcome.visual_error,
                         "follows_swapped": swapped, "final_loss": record.losses[-1],
                         "train_s": round(time.perf_counter() - start, 1)})
            follows = " ".join(f"{m} {v:.2f}" for m, v in swapped.items())
            print(f"{name:16s} {er_name:18s} success {rows[-1]['success']:.2f}  visual error "
                  f"{outcome.visual_error:.3f}  follows swapped {follows}", flush=True)
    print(f"chance: {1 / task.num_targets:.2f} (open loop can reach at most one of {task.num_targets} targets)")
    if args.out is not None:
        # Training's arithmetic, and so every row, can differ between installations: the file says which made it.
        atomic_write_json(args.out, {"task": vars(task), "steps": args.steps, "seed": args.seed,
                                     "versions": run_versions(), "rows": rows})
    return 0
