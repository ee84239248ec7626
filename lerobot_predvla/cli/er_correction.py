"""`predvla er-correction`: error regression's departure from the exact open loop before the grasp, start by
start, against how the scripted expert's approach varies over the same official init states
(experiments/er_correction.py).

  predvla trace OUT/er_task7 --policy.path=CKPT --env.type=predvla_libero --env.task=libero_object \\
      '--env.task_ids=[7]' --env.init_states=true --eval.n_episodes=10 --eval.batch_size=1 ...
  predvla trace OUT/ol_task7 --policy.path=CKPT ... --eval.n_episodes=1 --policy.er_iterations=0
  predvla er-correction --trace OUT/er_task7 --open-loop OUT/ol_task7 --out OUT

Each --trace pairs with the --open-loop of its task (one episode suffices: exact open loop reads no observation).
Runs the scripted expert from the same official init states (physics only, seconds per start), then writes
OUT/correction.json, correction.md and correction.png.
"""

import argparse
import shlex
import sys
from pathlib import Path

from lerobot_predvla.experiments.er_correction import (
    REPORT_MD,
    expert_approaches,
    load_trace_run,
    task_correction,
    write_report,
)
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("er-correction", help="error regression's correction before the grasp vs the expert's",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trace", type=Path, action="append", required=True, metavar="DIR",
                   help="`predvla trace` OUT of error regression on one task, official init states 0..n-1")
    p.add_argument("--open-loop", type=Path, action="append", required=True, metavar="DIR",
                   help="`predvla trace` OUT of the same checkpoint with --policy.er_iterations=0, same task")
    p.add_argument("--suite", default="libero_object")
    p.add_argument("--cap", type=int, default=PAPER_EPISODE_LENGTH, help="the expert's step cap")
    p.add_argument("--out", type=Path, required=True, help="directory for correction.json/.md/.png")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        ers = [load_trace_run(d) for d in args.trace]
        tasks_traced = [r.task_id for r in ers]
        if len(set(tasks_traced)) != len(tasks_traced):
            raise ValueError(f"--trace: one directory per task, got tasks {tasks_traced}.")
        open_loops = {run.task_id: run for run in map(load_trace_run, args.open_loop)}
        for run_ in ers:
            if run_.open_loop:
                raise ValueError(f"--trace {run_.path} ran with --policy.er_iterations=0 (exact open loop).")
            if run_.task_id not in open_loops:
                raise ValueError(f"--trace {run_.path} is task {run_.task_id}; no --open-loop trace has that task.")
            if not open_loops[run_.task_id].open_loop:
                raise ValueError(f"--open-loop {open_loops[run_.task_id].path} did not run with "
                                 "--policy.er_iterations=0.")
            if open_loops[run_.task_id].checkpoint != run_.checkpoint:
                raise ValueError(f"--trace {run_.path} and its --open-loop trace use different checkpoints.")
        expert = {r.task_id: expert_approaches(args.suite, r.task_id, list(range(len(r.actions))), args.cap)
                  for r in ers}
        tasks = [task_correction(r, open_loops[r.task_id], expert[r.task_id]) for r in ers]
    except ValueError as err:
        print(f"predvla er-correction: error: {err}", file=sys.stderr)
        return 2
    commands = [r.command() for r in [*ers, *open_loops.values()]]
    commands.append("predvla " + shlex.join(sys.argv[1:]))
    write_report(args.out, tasks, expert, commands)
    print((args.out / REPORT_MD).read_text())
    return 0
