"""`predvla blind-replay`: one scripted-expert plan per task replayed with no observation on other official init states.

For each task: the expert's plan from official init state `--source-state` (default 0), and a second plan from the
official init state whose object placements are nearest their mean over the task's official init states; each
replayed action by action on `--states` (default 1-20) after the settle steps, then idle up to `--cap` (default 600,
the paper's). Writes OUT/tasks/SUITE/taskK.json per task (atomically; a task already there under the same settings is
not run again, so an interrupted run continues where it stopped), then OUT/report.json (suite -> task ->
successes, episodes), OUT/report.md and OUT/blind_replay.png. Physics only, no rendering: one environment at a time.

  predvla blind-replay --suites libero_object
  predvla blind-replay   # all four suites, resuming

`--style teleop --diversity D`: the plans are the teleoperator model's demonstrations from the source states (as
`predvla demos --style teleop --diversity D` records them; the episode on state k is seeded by seed + k) instead of
the scripted expert's. The settings of every per-task file and report.json's entries name the style (and diversity);
default OUT: results/blind_replay_teleop.

  predvla blind-replay --suites libero_object --tasks 0 --states 1-19 --style teleop

`--resets-seed S --episodes N [--placement-spread-cm P]`: the plans (still recorded from official init states) are
replayed on randomised resets instead of official init states: episode i starts exactly where `lerobot-eval
--env.type=predvla_libero --env.init_states=false --seed=S [--env.placement_spread_cm=P]` starts episode i of the
task (reset seed S + i, the same placement shift, no arm start noise, LeRobot's 10 settle steps). Each per-task file
records every episode's reset seed (and placement record); report.json's entries name the set. Default OUT:
results/blind_replay_resetsS[_placedPcm][_teleop].

  predvla blind-replay --suites libero_object --tasks 2,3,6 --resets-seed 3000 --episodes 10 --placement-spread-cm 3

`--cross-task`: what ignoring the instruction gets. The state-0 plan of each task in `--tasks` (the plan tasks) is
replayed on the official init states `--states` of every other task of the same scene (or of the evaluated tasks
listed after the flag), success judged by the evaluated task's goal. Only tasks that share one scene are paired
(libero_goal: all ten); other tasks are left out, and refused when listed after the flag. Writes
OUT/plans/SUITE/taskA.json (the plan of task A), OUT/tasks/SUITE/taskB.json (evaluated task B, per plan task;
resumable plan by plan), then OUT/report.json (plan task x evaluated task), OUT/report.md and OUT/cross_task.png, with
each evaluated task's own plan on the same states read from the own-task results (`--own-out`, the same episodes:
replays are deterministic). Default OUT: results/blind_replay_cross.

  predvla blind-replay --cross-task --suites libero_goal --states 1-2
  predvla blind-replay --cross-task 3,5 --suites libero_goal --tasks 0 --states 1
"""

import argparse
import shlex
import sys
import time
from pathlib import Path

from tqdm import tqdm

from lerobot_predvla.cli.arguments import int_list
from lerobot_predvla.cli.demos import add_style_arguments
from lerobot_predvla.columns import SUITES
from lerobot_predvla.sims.libero.blind_replay import (
    DEFAULT_OUT,
    DEFAULT_STATES,
    TASKS_DIR,
    Settings,
    default_folder,
    episodes_per_task,
    load_task,
    run_task,
    starts_of,
    style_of,
    task_path,
    write_report,
)
from lerobot_predvla.sims.libero.blind_replay_cross import (
    DEFAULT_CROSS_OUT,
    pairs_to_run,
    plan_for,
    run_evaluated_task,
)
from lerobot_predvla.sims.libero.cross_task_report import write_cross_report
from lerobot_predvla.sims.libero.env import num_tasks
from lerobot_predvla.sims.libero.eval_resets import ResetSpec
from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN, HALF_TURN_RULES
from lerobot_predvla.sims.libero.expert.teleop import DEFAULT_STYLE
from lerobot_predvla.sims.libero.object_shift import PATTERNS, ShiftSpec
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH
from lerobot_predvla.utils.io import atomic_write_json

ALL_OTHERS: tuple[int, ...] = ()  # --cross-task with no ids: every other task of the suite


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
    p.add_argument("--tasks", type=int_list("--tasks"), default=None, help="task ids, e.g. 0,2 or 0-4 (default: all)")
    p.add_argument("--states", type=int_list("--states"), default=None,
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
    add_style_arguments(p, "the plan recorded from the source state")
    p.add_argument("--resets-seed", type=int, default=None,
                   help="replay on randomised resets instead of official init states: episode i starts as lerobot-eval "
                        "--env.type=predvla_libero --env.init_states=false --seed=RESETS_SEED starts episode i")
    p.add_argument("--episodes", type=int, default=None,
                   help="with --resets-seed: episodes per task, with reset seeds RESETS_SEED + 0 ... EPISODES - 1 "
                        "(default 10)")
    p.add_argument("--placement-spread-cm", type=float, default=0.0,
                   help="with --resets-seed: shift every movable object after each reset as lerobot-eval's "
                        "--env.placement_spread_cm does (default 0: none)")
    p.add_argument("--cross-task", type=int_list("--cross-task"), nargs="?", const=ALL_OTHERS, default=None,
                   metavar="IDS", help="replay each plan on other tasks of the same scene instead of its own: on the "
                   "evaluated task ids IDS, or with no IDS on every other task of the suite")
    p.add_argument("--own-out", type=Path, default=DEFAULT_OUT,
                   help=f"with --cross-task: the own-task results the report sets beside (default {DEFAULT_OUT})")
    p.add_argument("--out", type=Path, default=None,
                   help=f"output folder (default {DEFAULT_OUT}[_resetsS[_placedPcm]][_teleop] by --resets-seed, "
                        f"--placement-spread-cm and --style; with --cross-task {DEFAULT_CROSS_OUT})")
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
    if args.style != DEFAULT_STYLE:
        words += ["--style", args.style, "--diversity", f"{diversity(args):g}"]
    if args.resets_seed is not None:
        words += ["--resets-seed", str(args.resets_seed), "--episodes", str(resets(args).episodes)]
        if args.placement_spread_cm:
            words += ["--placement-spread-cm", f"{args.placement_spread_cm:g}"]
    if args.object_shift_cm:
        words += ["--object-shift-cm", f"{args.object_shift_cm:g}", "--object-shift-pattern", args.object_shift_pattern,
                  "--object-shift-directions", str(args.object_shift_directions)]
    if args.cross_task is not None:
        words.insert(2, "--cross-task")
        if tuple(args.cross_task) != ALL_OTHERS:
            words.insert(3, ",".join(map(str, args.cross_task)))
        if args.own_out != DEFAULT_OUT:
            words += ["--own-out", str(args.own_out)]
    if args.out != default_out(args):
        words += ["--out", str(args.out)]
    return shlex.join(words)


def default_out(args: argparse.Namespace) -> Path:
    if args.cross_task is not None:
        return DEFAULT_CROSS_OUT
    return default_folder(args.style, resets(args))


def resets(args: argparse.Namespace) -> ResetSpec:
    """--resets-seed, --episodes (10 when not given) and --placement-spread-cm; ValueError naming the flags."""
    if args.resets_seed is None and args.episodes is not None:
        raise ValueError(f"--episodes {args.episodes} needs --resets-seed (on official init states: --states)")
    return ResetSpec(seed=args.resets_seed, episodes=10 if args.episodes is None else args.episodes,
                     placement_spread_cm=args.placement_spread_cm)


def diversity(args: argparse.Namespace) -> float:
    """--diversity, 1 (the committed setting) when not given."""
    return 1.0 if args.diversity is None else args.diversity


def kind_of(settings: dict) -> dict:
    """What one report holds one of: the plans' style (and diversity) and the set of starts (`starts_of`)."""
    return {**style_of(settings), **starts_of(settings)}


def other_kind(out: Path, suites: list[str], settings: Settings) -> Path | None:
    """A per-task file under `out` made with another style, diversity or set of starts than `settings`."""
    mine = kind_of(settings.as_dict())
    for suite in suites:
        for path in sorted((Path(out) / TASKS_DIR / suite).glob("task*.json")):
            done = load_task(path)
            if done is not None and kind_of(done.get("settings", {})) != mine:
                return path
    return None


def run(args: argparse.Namespace) -> int:
    if args.resets_seed is not None and args.states is not None:
        raise SystemExit("--states lists official init states to replay on; --resets-seed replays on randomised "
                         "resets instead (--episodes): pass one or the other")
    states = tuple(args.states) if args.states is not None else () if args.resets_seed is not None else DEFAULT_STATES
    if args.cap < 1:
        raise SystemExit(f"--cap must be >= 1, got {args.cap}")
    if args.source_state < 0:
        raise SystemExit(f"--source-state must be >= 0, got {args.source_state}")
    if args.source_state in states and not args.object_shift_cm:
        raise SystemExit(f"--states {','.join(map(str, states))} includes --source-state {args.source_state}: the "
                         "state-0 plan is replayed on states other than its own (unless --object-shift-cm moves the "
                         "object from it)")
    try:
        shift = ShiftSpec(object_cm=args.object_shift_cm, pattern=args.object_shift_pattern,
                          directions=args.object_shift_directions)
    except ValueError as err:
        raise SystemExit(str(err).replace("--env.object_shift_", "--object-shift-").replace("_", "-")) from err
    if args.diversity is not None and args.style != "teleop":
        raise SystemExit(f"--diversity {args.diversity} needs --style teleop (the script has no diversity)")
    try:
        settings = Settings(states=states, source_state=args.source_state, cap=args.cap, seed=args.seed,
                            half_turn=args.half_turn, shift=shift, style=args.style, diversity=diversity(args),
                            resets=resets(args))
    except ValueError as err:
        raise SystemExit(str(err)) from err
    if args.out is None:
        args.out = default_out(args)
    if args.cross_task is not None:
        if args.object_shift_cm or args.style != DEFAULT_STYLE or settings.resets.active:
            raise SystemExit("--cross-task replays scripted plans on other tasks' official states; --object-shift-cm, "
                             "--resets-seed and --style teleop are not supported with it")
        return run_cross(args, settings)
    mixed = other_kind(args.out, args.suites, settings)
    if mixed is not None:
        raise SystemExit(f"{mixed} holds plans of another style or on other starts "
                         f"({kind_of(load_task(mixed)['settings'])}); one report holds one style on one set of "
                         "starts: pass another --out")
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
    """The command (one line per suite where their tasks differ) that reproduces the report as it stands: the
    suites and tasks OUT holds, under these settings (with --cross-task: the suites and tasks asked for)."""
    if args.cross_task is not None:
        return command_line(args)
    held = {suite: sorted(int(p.stem.removeprefix("task")) for p in (args.out / TASKS_DIR / suite).glob("task*.json"))
            for suite in SUITES}
    held = {suite: tasks for suite, tasks in held.items() if tasks}
    if not held:
        held = {suite: list(range(num_tasks(suite))) for suite in args.suites}
    whole = {suite: None if tasks == list(range(num_tasks(suite))) else tasks for suite, tasks in held.items()}
    if len(set(map(str, whole.values()))) == 1:  # one --tasks (or none) fits every suite held
        return command_line(argparse.Namespace(**{**vars(args), "suites": list(whole),
                                                  "tasks": next(iter(whole.values()))}))
    return "\n".join(command_line(argparse.Namespace(**{**vars(args), "suites": [suite], "tasks": tasks}))
                     for suite, tasks in whole.items())


def expected_all() -> dict[str, int]:
    return {suite: num_tasks(suite) for suite in SUITES}


def run_cross(args: argparse.Namespace, settings: Settings) -> int:
    """`--cross-task`: the plans of `--tasks` replayed on the evaluated tasks (see the module docstring)."""
    work = {}
    for suite in args.suites:
        n = num_tasks(suite)
        plan_tasks = args.tasks if args.tasks is not None else list(range(n))
        evaluated = list(args.cross_task) or list(range(n))
        bad = [t for t in {*plan_tasks, *evaluated} if not 0 <= t < n]
        if bad:
            raise SystemExit(f"--tasks / --cross-task {sorted(bad)}: {suite} has tasks 0-{n - 1}")
        try:
            work[suite] = pairs_to_run(args.out, suite, plan_tasks, evaluated, settings,
                                       strict=bool(args.cross_task))
        except ValueError as err:
            raise SystemExit(f"--cross-task: {err}") from err
    pending = sum(len(pairs) for pairs in work.values())
    print(f"{pending} (plan task, evaluated task) pair(s) to run under {args.out}")
    t0 = time.time()
    with tqdm(total=pending * len(settings.states), desc="cross-task blind replay", unit="episode") as bar:
        for suite, pairs in work.items():
            plans = {a: plan_for(args.out, suite, a, settings) for a in sorted({p.plan_task for p in pairs})}
            for b in sorted({p.evaluated_task for p in pairs}):
                mine = {p.plan_task: plans[p.plan_task] for p in pairs if p.evaluated_task == b}
                bar.set_postfix_str(f"{suite} evaluated task {b}")
                result = run_evaluated_task(args.out, suite, b, mine, settings, progress=lambda: bar.update(1))
                tqdm.write(f"{suite} evaluated task {b}: " + ", ".join(
                    f"plan {a} {result['plans'][str(a)]['successes']}/{result['plans'][str(a)]['episodes']}"
                    for a in mine))
    report = write_cross_report(args.out, command_for_report(args), args.own_out)
    if not report:
        print(f"no results under {args.out}", file=sys.stderr)
        return 1
    print(f"wrote {args.out}/report.json, report.md, cross_task.png ({time.time() - t0:.0f} s)")
    return 0
