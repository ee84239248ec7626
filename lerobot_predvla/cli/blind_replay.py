"""`predvla blind-replay`: one scripted-expert plan per task replayed with no observation on other official init states.

For each task: the expert's plan from official init state `--source-state` (default 0), and a second plan from the
official init state whose object placements are nearest their mean over the task's official init states; each
replayed action by action on `--states` (default 1-20) after the settle steps, then idle up to `--cap` (default 600,
the paper's). Writes OUT/tasks/SUITE/taskK.json per task (atomically; a task already there under the same settings is
not run again, so an interrupted run continues where it stopped), then OUT/report.json (suite -> task ->
successes, episodes), OUT/report.md and OUT/blind_replay.png. Physics only, no rendering: one environment at a time.

  predvla blind-replay --suites libero_object
  predvla blind-replay   # all four suites, resuming
"""

import argparse
import shlex
import sys
import time
from pathlib import Path

from tqdm import tqdm

from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.blind_replay import (
    DEFAULT_OUT,
    DEFAULT_STATES,
    Settings,
    episodes_per_task,
    load_task,
    run_task,
    task_path,
    write_report,
)
from lerobot_predvla.sims.libero.env import num_tasks
from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN, HALF_TURN_RULES
from lerobot_predvla.sims.libero.object_shift import PATTERNS, ShiftSpec
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH
from lerobot_predvla.utils.io import atomic_write_json


def _ints(flag: str):
    def parse(text: str) -> list[int]:
        out = []
        try:
            for part in text.split(","):
                part = part.strip()
                if not part:
                    continue
                if "-" in part:
                    lo, hi = (int(v) for v in part.split("-", 1))
                    if hi < lo:
                        raise ValueError(part)
                    out.extend(range(lo, hi + 1))
                else:
                    out.append(int(part))
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"{flag} expects integers and ranges such as 1-20 or 0,3,5; got "
                                             f"{text!r}") from err
        if not out:
            raise argparse.ArgumentTypeError(f"{flag} is empty")
        return sorted(set(out))

    return parse


def _suites(text: str) -> list[str]:
    suites = [s.strip() for s in text.split(",") if s.strip()]
    unknown = [s for s in suites if s not in SUITES]
    if unknown or not suites:
        raise argparse.ArgumentTypeError(f"--suites expects a comma-separated subset of {', '.join(SUITES)}; "
                                         f"got {text!r}")
    return suites


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("blind-replay", help="replay one scripted-expert plan per task without observations",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--suites", type=_suites, default=list(SUITES), help="comma-separated (default: all four)")
    p.add_argument("--tasks", type=_ints("--tasks"), default=None, help="task ids, e.g. 0,2 or 0-4 (default: all)")
    p.add_argument("--states", type=_ints("--states"), default=None,
                   help="official init states the plans are replayed on (default 1-20)")
    p.add_argument("--source-state", type=int, default=0,
                   help="official init state the first plan is recorded from (default 0)")
    p.add_argument("--cap", type=int, default=PAPER_EPISODE_LENGTH,
                   help=f"control steps after the settle steps, plan and idle steps together (default "
                        f"{PAPER_EPISODE_LENGTH}, the paper's cap); also the expert's cap when recording a plan")
    p.add_argument("--seed", type=int, default=0, help="fixture poses of the episode on state k: seed + k")
    p.add_argument("--half-turn", choices=HALF_TURN_RULES, default=DEFAULT_HALF_TURN,
                   help="the expert's grasp rule when recording a plan (as `predvla demos --half-turn`)")
    p.add_argument("--object-shift-cm", type=float, default=0.0,
                   help="shift the object to pick on the replay states by this many cm, as lerobot-eval's "
                        "--env.object_shift_cm does on official init state k (default 0: none)")
    p.add_argument("--object-shift-pattern", choices=PATTERNS, default="ring", help="as --env.object_shift_pattern")
    p.add_argument("--object-shift-directions", type=int, default=8, help="as --env.object_shift_directions")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    p.set_defaults(func=run)


def command_line(args: argparse.Namespace) -> str:
    words = ["predvla", "blind-replay"]
    if args.suites != list(SUITES):
        words += ["--suites", ",".join(args.suites)]
    if args.tasks is not None:
        words += ["--tasks", ",".join(map(str, args.tasks))]
    if args.states is not None and tuple(args.states) != DEFAULT_STATES:
        words += ["--states", ",".join(map(str, args.states))]
    if args.source_state != 0:
        words += ["--source-state", str(args.source_state)]
    if args.cap != PAPER_EPISODE_LENGTH:
        words += ["--cap", str(args.cap)]
    if args.seed != 0:
        words += ["--seed", str(args.seed)]
    if args.object_shift_cm:
        words += ["--object-shift-cm", f"{args.object_shift_cm:g}", "--object-shift-pattern", args.object_shift_pattern,
                  "--object-shift-directions", str(args.object_shift_directions)]
    if args.out != DEFAULT_OUT:
        words += ["--out", str(args.out)]
    return shlex.join(words)


def run(args: argparse.Namespace) -> int:
    states = tuple(args.states) if args.states is not None else DEFAULT_STATES
    if args.cap < 1:
        raise SystemExit(f"--cap must be >= 1, got {args.cap}")
    if args.source_state < 0:
        raise SystemExit(f"--source-state must be >= 0, got {args.source_state}")
    if args.source_state in states:
        raise SystemExit(f"--states {','.join(map(str, states))} includes --source-state {args.source_state}: the "
                         "state-0 plan is replayed on states other than its own")
    try:
        shift = ShiftSpec(object_cm=args.object_shift_cm, pattern=args.object_shift_pattern,
                          directions=args.object_shift_directions)
    except ValueError as err:
        raise SystemExit(str(err).replace("--env.object_shift_", "--object-shift-").replace("_", "-")) from err
    settings = Settings(states=states, source_state=args.source_state, cap=args.cap, seed=args.seed,
                        half_turn=args.half_turn, shift=shift)
    expected = {suite: num_tasks(suite) for suite in args.suites}
    jobs = []
    for suite in args.suites:
        ids = args.tasks if args.tasks is not None else list(range(expected[suite]))
        bad = [t for t in ids if not 0 <= t < expected[suite]]
        if bad:
            raise SystemExit(f"--tasks {bad}: {suite} has tasks 0-{expected[suite] - 1}")
        for task_id in ids:
            path = task_path(args.out, suite, task_id)
            done = load_task(path)
            if done is not None and done.get("settings") != settings.as_dict():
                raise SystemExit(f"{path} was run with other settings ({done.get('settings')}); pass another --out "
                                 "or delete it to run that task again")
            if done is None:
                jobs.append((suite, task_id))
    skipped = sum(len(args.tasks) if args.tasks is not None else expected[s] for s in args.suites) - len(jobs)
    if skipped:
        print(f"{skipped} task(s) already done under {args.out}/tasks (same settings): not run again")
    t0 = time.time()
    with tqdm(total=len(jobs) * episodes_per_task(settings), desc="blind replay", unit="episode") as bar:
        for suite, task_id in jobs:
            bar.set_postfix_str(f"{suite} task {task_id}")
            result = run_task(suite, task_id, settings, progress=lambda: bar.update(1))
            atomic_write_json(task_path(args.out, suite, task_id), result)
            first, second = result["plans"]["state0"], result["plans"]["nearest_mean"]
            tqdm.write(f"{suite} task {task_id}: state-0 plan {first['successes']}/{first['episodes']}, nearest-mean "
                       f"plan (state {second['source_state']}) {second['successes']}/{second['episodes']} "
                       f"({result['seconds']:.0f} s)")
            write_report(args.out, command_for_report(args), expected_all())
    report = write_report(args.out, command_for_report(args), expected_all())
    if not report:
        print(f"no results under {args.out}", file=sys.stderr)
        return 1
    print(f"wrote {args.out}/report.json, report.md, blind_replay.png ({time.time() - t0:.0f} s)")
    return 0


def command_for_report(args: argparse.Namespace) -> str:
    """The command that reproduces the whole report: every suite, every task, under these settings."""
    full = argparse.Namespace(**{**vars(args), "suites": list(SUITES), "tasks": None})
    return command_line(full)


def expected_all() -> dict[str, int]:
    return {suite: num_tasks(suite) for suite in SUITES}
