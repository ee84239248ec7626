"""`predvla sweep`: train and evaluate configurations x suites x seeds from a sweep file, resumably."""

import argparse
import re
import shlex
import sys
from datetime import datetime, timedelta
from pathlib import Path

from lerobot_predvla.sweep import Runner, Sweep, SweepError, SweepStopped, parse_shard
from lerobot_predvla.sweep.status import format_status, sweep_status


def _ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",") if x]


def _names(text: str) -> list[str]:
    return [x for x in text.split(",") if x]


def stop_time(text: str) -> datetime:
    """`--stop-at`: HH:MM (its next occurrence, local time) or an ISO 8601 date and time (local unless it says)."""
    now = datetime.now().astimezone()
    try:
        if re.fullmatch(r"\d{1,2}:\d{2}", text):
            hour, minute = map(int, text.split(":"))
            at = now.replace(hour=hour, minute=minute, second=0, microsecond=0)
            return at if at > now else at + timedelta(days=1)
        at = datetime.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected HH:MM or an ISO 8601 date and time such as 2026-12-08T01:00, got {text!r}") from None
    return at if at.tzinfo else at.astimezone()


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="run lerobot-train + lerobot-eval for every configuration x suite x seed of a sweep file",
        description=__doc__ + " Defaults follow the paper (50 rollouts per task from the official initial "
        "states, 600-step cap, 30,000 training steps, batch 32); the flags below shrink them.",
    )
    parser.add_argument("sweep_file", type=Path, help="YAML or JSON sweep file (see configs/sweeps/).")
    parser.add_argument("--runs-dir", type=Path, required=True, help="Where checkpoints, logs and records go.")
    parser.add_argument("--shard", default="0/1", help="Run only shard i of n (i/n, 0-based) of the training units.")
    parser.add_argument("--configs", type=_names, default=None, help="Comma-separated configuration names.")
    parser.add_argument("--seeds", type=_ints, default=None,
                        help="Comma-separated seeds (replace the file's; a configuration that names its own seeds "
                             "keeps those among them).")
    parser.add_argument("--suites", type=_names, default=None, help="Comma-separated suites (replace the file's).")
    parser.add_argument("--steps", type=int, default=None, help="Training steps for every configuration.")
    parser.add_argument("--n-episodes", type=int, default=None, help="Rollouts per task for every configuration.")
    parser.add_argument("--eval-tasks", type=_ints, default=None,
                        help="Comma-separated task ids to evaluate, task by task (replace the file's eval.tasks).")
    parser.add_argument("--episode-length", type=int, default=None, help="Control-step cap per rollout.")
    parser.add_argument("--device", default=None, help="Device for training and evaluation (e.g. cpu, cuda).")
    parser.add_argument("--accelerate-processes", type=int, default=None,
                        help="Train each run with `accelerate launch --multi_gpu --num_processes=N`.")
    parser.add_argument("--eval-workers", type=int, default=None,
                        help="Task parts of an evaluation run at once, one lerobot-eval process each (with eval.tasks; "
                             "e.g. 2 on a 2-core CPU, with OMP_NUM_THREADS=1).")
    parser.add_argument("--stop-at", type=stop_time, default=None, metavar="TIME",
                        help="Start no data stage, training or evaluation part after TIME (HH:MM, its next "
                             "occurrence, or an ISO 8601 date and time); those running then finish, and the same "
                             "command later resumes the rest. Set it a part's length before the machine goes away.")
    parser.add_argument("--dry-run", action="store_true", help="Print this shard's commands and run nothing.")
    parser.add_argument("--status", action="store_true",
                        help="Print where each run stands (training, evaluation parts finished, successes so far, "
                             "time left at the finished parts' median) and run nothing.")
    parser.add_argument("--data-only", action="store_true",
                        help="Make the suites' datasets (the file's `data` stages, each timed in "
                             "RUNS_DIR/data/<suite>.json) and stop before any training.")
    parser.add_argument("--train-only", action="store_true",
                        help="Train (or resume) what the pending runs need, publish as the file says, and evaluate "
                             "nothing; a later call without it evaluates from the finished trainings.")
    parser.set_defaults(func=run)


def apply_flags(sweep: Sweep, args: argparse.Namespace) -> None:
    """Command-line values replace the sweep file's, per-configuration values included."""
    s = sweep.settings
    for spec in sweep.configs.values():
        if args.seeds is not None and spec.seeds is not None:  # a configuration's own seeds: those also asked for
            spec.seeds = [x for x in spec.seeds if x in args.seeds]
        if args.suites is not None and spec.suites is not None:  # likewise its own suites
            spec.suites = [x for x in spec.suites if x in args.suites]
        if args.steps is not None:
            spec.steps = None
            if spec.lr_sweep is not None:  # the candidates shrink with the runs (their held-out loss at the end)
                spec.lr_sweep.steps, spec.lr_sweep.eval_every = args.steps, None
        if args.n_episodes is not None:
            spec.n_episodes = None
    s.seeds = args.seeds if args.seeds is not None else s.seeds
    s.suites = args.suites if args.suites is not None else s.suites
    s.steps = args.steps or s.steps
    s.n_episodes = args.n_episodes or s.n_episodes
    s.episode_length = args.episode_length or s.episode_length
    s.eval_tasks = args.eval_tasks or s.eval_tasks
    if args.device:
        s.train_device = s.eval_device = args.device
    s.accelerate_processes = args.accelerate_processes or s.accelerate_processes
    s.eval_workers = args.eval_workers or s.eval_workers


def run(args: argparse.Namespace) -> int:
    try:
        sweep = Sweep.load(args.sweep_file)
        apply_flags(sweep, args)
        sweep.validate(args.sweep_file)
        shard = parse_shard(args.shard)
        runner = Runner(sweep, args.runs_dir.resolve(), stop_at=args.stop_at)
        if args.status:
            print(format_status(sweep_status(runner, args.configs, shard), sweep.settings.eval_workers))
            return 0
        if args.dry_run:
            for command in runner.pending_commands(args.configs, shard):
                print(shlex.join(command))
            return 0
        if args.data_only:
            made = []
            try:
                for suite in sweep.settings.suites:
                    made.append(runner.make_data(suite))
            except SweepStopped as stop:
                print_stopped(str(stop))
                return 0 if all(made) else 1
            print(f"predvla sweep: datasets of {sum(made)} of {len(made)} suites ready; stage times in "
                  f"{args.runs_dir / 'data'}")
            return 0 if all(made) else 1
        outcome = runner.run(args.configs, shard, train_only=args.train_only)
    except SweepError as err:
        print(f"predvla sweep: error: {err}", file=sys.stderr)
        return 2
    if args.train_only:
        print(f"predvla sweep: {len(outcome['trained'])} trainings finished, {len(outcome['failed'])} failed "
              f"(no evaluation); checkpoints in {args.runs_dir / 'train'}")
    else:
        print(f"predvla sweep: {len(outcome['done'])} runs done, {len(outcome['skipped'])} already done, "
              f"{len(outcome['failed'])} failed; records in {args.runs_dir / 'records'}")
    for stop in outcome["stopped"]:
        print_stopped(stop)
    return 1 if outcome["failed"] else 0


def print_stopped(why: str) -> None:
    print(f"predvla sweep: stopped, {why}; the same command resumes what is left", file=sys.stderr)
