"""`predvla er-timing`: when error regression starts the plan's lift against the exact open loop, start by start, and
whether an early lift goes with failure (experiments/er_timing.py).

  predvla trace OUT/er_task2 --policy.path=CKPT --env.type=predvla_libero --env.task=libero_object \\
      '--env.task_ids=[2]' --env.init_states=true --env.episode_length=160 --eval.n_episodes=50 \\
      --eval.batch_size=10 --seed=0 ...
  predvla trace OUT/ol_task2 --policy.path=CKPT ... --eval.n_episodes=1 --policy.er_iterations=0
  predvla er-timing --trace OUT/er_task2 --open-loop OUT/ol_task2 \\
      --outcomes RUNS/eval/CONFIG/libero_object/seed0/task2/eval_info.json --test-states 10-49 --out OUT

--outcomes takes the successes from a full evaluation of the same checkpoint and starts (the trace must use its
batch size, seed and OMP_NUM_THREADS, so that it repeats its episodes); without it, from the trace's own evaluation.
Writes OUT/timing.json, timing.md and timing.png.
"""

import argparse
import shlex
import sys
from pathlib import Path

from lerobot_predvla.experiments.er_correction import load_trace_run
from lerobot_predvla.experiments.er_timing import REPORT_MD, episode_outcomes, write_report


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("er-timing", help="error regression's lift step vs the open loop's, and the outcomes",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trace", type=Path, required=True, metavar="DIR",
                   help="`predvla trace` OUT of error regression on one task, official init states 0..n-1")
    p.add_argument("--open-loop", type=Path, required=True, metavar="DIR",
                   help="`predvla trace` OUT of the same checkpoint with --policy.er_iterations=0, same task")
    p.add_argument("--outcomes", type=Path, metavar="EVAL_INFO",
                   help="eval_info.json whose successes of this task are the episodes' outcomes "
                        "(default: the trace's own evaluation)")
    p.add_argument("--test-states", metavar="A-B",
                   help="official init states of the test set, e.g. 10-49 (default: only every traced start)")
    p.add_argument("--out", type=Path, required=True, help="directory for timing.json/.md/.png")
    p.set_defaults(func=run)


def state_range(text: str) -> list[int]:
    try:
        first, last = (int(x) for x in text.split("-"))
    except ValueError as err:
        raise ValueError(f"--test-states: expected A-B (e.g. 10-49), got {text!r}.") from err
    if not 0 <= first <= last:
        raise ValueError(f"--test-states: expected 0 <= A <= B, got {text!r}.")
    return list(range(first, last + 1))


def run(args: argparse.Namespace) -> int:
    try:
        test_states = state_range(args.test_states) if args.test_states else None
        er, open_loop = load_trace_run(args.trace), load_trace_run(args.open_loop)
        if er.open_loop:
            raise ValueError(f"--trace {er.path} ran with --policy.er_iterations=0 (exact open loop).")
        if not open_loop.open_loop:
            raise ValueError(f"--open-loop {open_loop.path} did not run with --policy.er_iterations=0.")
        if (er.task_id, er.checkpoint) != (open_loop.task_id, open_loop.checkpoint):
            raise ValueError(f"--trace {er.path} and --open-loop {open_loop.path} differ in task or checkpoint.")
        outcomes = args.outcomes or er.output_dir / "eval_info.json"
        successes = episode_outcomes(outcomes, er.task_id)
        commands = [er.command(), open_loop.command(), "predvla " + shlex.join(sys.argv[1:])]
        write_report(args.out, er, open_loop, successes, test_states, commands)
    except ValueError as err:
        print(f"predvla er-timing: error: {err}", file=sys.stderr)
        return 2
    print((args.out / REPORT_MD).read_text())
    return 0
