"""When error regression switches the plan's phases, against the exact open loop, and whether that decides the
episode.

Exact open loop reads no observation, so on every official init state of a task it commands one action sequence
whose plan switches phase at fixed steps: the gripper closes (`gripper_events`: the gripper command turns positive in
raw units), then the lift starts (the first step at or after the close whose z action exceeds LIFT_Z). Error
regression, traced on the same starts (`predvla trace`, episode i from official init state i, or from the i-th
randomised reset of the evaluation's seed with `--env.init_states=false`), runs the same plan
with its posteriors moved by the observations, and can switch a phase a step earlier or later. Per start this
compares its phase steps with the open loop's and relates the lift's shift to the episode's outcome: Fisher's exact
test, one-sided, of failure against a lift started before the open loop's, on the starts chosen as the test set.

The outcomes come from the trace's own evaluation or from a full evaluation of the same checkpoint and starts
(`--outcomes`, its eval_info.json): at the same batch, seed and thread count a trace repeats the evaluation's
episodes step for step up to its own cap, so a shorter trace can time the phases of a longer evaluation.

Command (from the repository root):

  predvla trace OUT/er_task2 --policy.path=CKPT --env.type=predvla_libero --env.task=libero_object \\
      '--env.task_ids=[2]' --env.init_states=true --env.episode_length=160 --eval.n_episodes=50 \\
      --eval.batch_size=10 --seed=0 ...
  predvla trace OUT/ol_task2 --policy.path=CKPT ... --eval.n_episodes=1 --policy.er_iterations=0
  python -m research.er_timing --trace OUT/er_task2 --open-loop OUT/ol_task2 \\
      --outcomes RUNS/eval/CONFIG/libero_object/seed0/task2/eval_info.json --test-states 10-49 --out OUT

--outcomes takes the successes from a full evaluation of the same checkpoint and starts (the trace must use its
batch size, seed and OMP_NUM_THREADS, so that it repeats its episodes); without it, from the trace's own evaluation.
Writes OUT/timing.json, timing.md and timing.png.
"""

import argparse
import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from lerobot_predvla.sweep.eval_info import episode_successes
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text
from research.er_correction import TraceRun, close_step, load_trace_run

Z = 2  # the OSC z position delta
LIFT_Z = 0.5  # raw z action above which the hand rises (the plan's lift commands about +1, its descent about -0.3)
REPORT_JSON, REPORT_MD, FIGURE = "timing.json", "timing.md", "timing.png"
OFFICIAL = "official init states"  # the report's `starts` on the official init states
COMMAND = "python -m research.er_timing"


def lift_step(actions: np.ndarray, close: int | None) -> int | None:
    """First step at or after the gripper's close whose z action exceeds LIFT_Z; None without a close or a lift."""
    if close is None:
        return None
    rising = np.flatnonzero(np.asarray(actions)[close:, Z] > LIFT_Z)
    return int(close + rising[0]) if len(rising) else None


@dataclass
class EpisodeTiming:
    state: int
    close: int | None
    lift: int | None
    success: bool


def episode_outcomes(eval_info: Path, task_id: int) -> list[bool]:
    """Per episode of task `task_id`, in lerobot-eval's order, whether it succeeded (an eval_info.json)."""
    successes = episode_successes(eval_info)
    if str(task_id) not in successes:
        raise ValueError(f"{eval_info}: no successes of task {task_id} (it has tasks {list(successes)}).")
    return successes[str(task_id)]


def episode_timings(er: TraceRun, successes: list[bool]) -> list[EpisodeTiming]:
    if len(successes) < len(er.actions):
        raise ValueError(f"{er.path}: {len(er.actions)} traced episodes, but the outcomes name {len(successes)}.")
    rows = []
    for state, actions in enumerate(er.actions):  # state: the official init state, or the reset's episode index
        close = close_step(actions)
        rows.append(EpisodeTiming(state, close, lift_step(actions, close), successes[state]))
    return rows


def early_lift_test(episodes: list[EpisodeTiming], open_loop_lift: int, states: list[int]) -> dict:
    """On `states`: failures and successes of the episodes whose lift starts before the open loop's and of the
    others, and Fisher's exact test (one-sided: an early lift goes with failure)."""
    chosen = [e for e in episodes if e.state in set(states)]
    early = [e.lift is not None and e.lift < open_loop_lift for e in chosen]
    table = [[sum(1 for e, x in zip(chosen, early, strict=True) if x == row and e.success == outcome)
              for outcome in (False, True)] for row in (True, False)]
    odds, p = stats.fisher_exact(table, alternative="greater")
    return {"states": sorted({e.state for e in chosen}), "table": table, "odds_ratio": float(odds), "p": float(p)}


def _counts(table: list[list[int]]) -> str:
    (early_fail, early_ok), (other_fail, other_ok) = table
    return (f"lift early: {early_fail} failed, {early_ok} succeeded; not early: {other_fail} failed, "
            f"{other_ok} succeeded")


def markdown(report: dict) -> str:
    ol, tests = report["open_loop"], report["tests"]
    lines = [f"# When error regression switches the plan's phases: task {report['task_id']}", "",
             "Exact open loop closes the gripper at step {close} and starts the lift (z action above {z}) at step "
             "{lift}, on every start.".format(close=ol["close"], lift=ol["lift"], z=LIFT_Z), "",
             "Reproduce:", "", "```bash", *report["commands"], "```", "",
             f"| set | {report['starts']} | episodes | " + "early lift: failed / succeeded | "
             "not early: failed / succeeded | odds ratio | p (Fisher, one-sided) |", "|---|---|---|---|---|---|---|"]
    for name, t in tests.items():
        (a, b), (c, d) = t["table"]
        states = t["states"]
        span = f"{states[0]}-{states[-1]}" if states == list(range(states[0], states[-1] + 1)) else str(states)
        lines.append(f"| {name} | {span} | {a + b + c + d} | {a} / {b} | {c} / {d} | {t['odds_ratio']:.3g} | "
                     f"{t['p']:.2g} |")
    start = "state" if report["starts"] == OFFICIAL else "reset"
    lines += ["", "Per start (steps; - where the event does not happen):", "",
              f"| {start} | close | lift | lift - open loop's | success |", "|---|---|---|---|---|"]
    for e in report["episodes"]:
        shift = "-" if e["lift"] is None else f"{e['lift'] - ol['lift']:+d}"
        lines.append(f"| {e['state']} | {e['close'] if e['close'] is not None else '-'} | "
                     f"{e['lift'] if e['lift'] is not None else '-'} | {shift} | {'yes' if e['success'] else 'no'} |")
    return "\n".join(lines) + "\n"


def figure(er: TraceRun, open_loop: np.ndarray, episodes: list[EpisodeTiming], open_loop_lift: int,
           path: Path) -> None:
    """Left: the z action around the open loop's lift, every traced start (red: failed) against the open loop.
    Right: how many starts lift how many steps from the open loop's step, split by outcome."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    window = slice(max(open_loop_lift - 15, 0), open_loop_lift + 10)
    drawn = sorted(zip(er.actions, episodes, strict=True), key=lambda pair: not pair[1].success)  # failures on top
    for actions, e in drawn:
        steps = np.arange(len(actions))[window]
        left.plot(steps, actions[window, Z], color="tab:green" if e.success else "tab:red", lw=0.7, alpha=0.6)
    left.plot(np.arange(len(open_loop))[window], open_loop[window, Z], color="black", lw=2, label="exact open loop")
    left.plot([], [], color="tab:green", label="error regression, succeeded")
    left.plot([], [], color="tab:red", label="error regression, failed")
    left.axhline(LIFT_Z, color="grey", lw=0.5, ls="--")
    left.set_xlabel("control step")
    left.set_ylabel("z action (raw)")
    left.legend(fontsize=8)
    shifts = sorted({e.lift - open_loop_lift for e in episodes if e.lift is not None})
    counts = {outcome: [sum(1 for e in episodes if e.lift is not None and e.lift - open_loop_lift == s
                            and e.success == outcome) for s in shifts] for outcome in (False, True)}
    labels = [f"{s:+d}" for s in shifts]
    right.bar(labels, counts[False], color="tab:red", label="failed")
    right.bar(labels, counts[True], bottom=counts[False], color="tab:green", label="succeeded")
    right.set_xlabel("error regression's lift step - the open loop's")
    right.set_ylabel("starts")
    right.legend(fontsize=8)
    fig.suptitle(f"Task {er.task_id}: error regression's lift against the open loop's")
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=90)
    plt.close(fig)


def write_report(out: Path, er: TraceRun, open_loop: TraceRun, successes: list[bool],
                 test_states: list[int] | None, commands: list[str]) -> dict:
    ol_actions = open_loop.actions[0]
    ol_close = close_step(ol_actions)
    ol_lift = lift_step(ol_actions, ol_close)
    if ol_lift is None:
        raise ValueError(f"{open_loop.path}: the open loop never closes the gripper and lifts (z action above "
                         f"{LIFT_Z} after the close); there is no lift to time against.")
    episodes = episode_timings(er, successes)
    every = [e.state for e in episodes]
    tests = {"all traced starts": early_lift_test(episodes, ol_lift, every)}
    if test_states is not None:
        missing = sorted(set(test_states) - set(every))
        if missing:
            raise ValueError(f"--test-states: starts {missing} were not traced (0-{len(every) - 1}).")
        tests["test starts"] = early_lift_test(episodes, ol_lift, test_states)
    starts = OFFICIAL if er.official_states else f"randomised resets of seed {er.seed}"
    report = {"task_id": er.task_id, "checkpoint": er.checkpoint, "starts": starts, "lift_z": LIFT_Z,
              "open_loop": {"close": ol_close, "lift": ol_lift}, "tests": tests,
              "episodes": [asdict(e) for e in episodes], "commands": commands}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / REPORT_JSON, report)
    atomic_write_text(out / REPORT_MD, markdown(report))
    figure(er, ol_actions, episodes, ol_lift, out / FIGURE)
    return report


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=COMMAND, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trace", type=Path, required=True, metavar="DIR",
                   help="`predvla trace` OUT of error regression on one task, official init states 0..n-1 or "
                        "randomised resets")
    p.add_argument("--open-loop", type=Path, required=True, metavar="DIR",
                   help="`predvla trace` OUT of the same checkpoint with --policy.er_iterations=0, same task")
    p.add_argument("--outcomes", type=Path, metavar="EVAL_INFO",
                   help="eval_info.json whose successes of this task are the episodes' outcomes "
                        "(default: the trace's own evaluation)")
    p.add_argument("--test-states", metavar="A-B",
                   help="starts of the test set (official init states or the resets' episode indices), e.g. "
                        "10-49 (default: only every traced start)")
    p.add_argument("--out", type=Path, required=True, help="directory for timing.json/.md/.png")
    return p


def state_range(text: str) -> list[int]:
    try:
        first, last = (int(x) for x in text.split("-"))
    except ValueError as err:
        raise ValueError(f"--test-states: expected A-B (e.g. 10-49), got {text!r}.") from err
    if not 0 <= first <= last:
        raise ValueError(f"--test-states: expected 0 <= A <= B, got {text!r}.")
    return list(range(first, last + 1))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
    try:
        test_states = state_range(args.test_states) if args.test_states else None
        er = load_trace_run(args.trace, official_states=False)
        open_loop = load_trace_run(args.open_loop, official_states=False)
        if er.open_loop:
            raise ValueError(f"--trace {er.path} ran with --policy.er_iterations=0 (exact open loop).")
        if not open_loop.open_loop:
            raise ValueError(f"--open-loop {open_loop.path} did not run with --policy.er_iterations=0.")
        if (er.task_id, er.checkpoint) != (open_loop.task_id, open_loop.checkpoint):
            raise ValueError(f"--trace {er.path} and --open-loop {open_loop.path} differ in task or checkpoint.")
        outcomes = args.outcomes or er.output_dir / "eval_info.json"
        successes = episode_outcomes(outcomes, er.task_id)
        commands = [er.command(), open_loop.command(), f"{COMMAND} {shlex.join(argv)}"]
        write_report(args.out, er, open_loop, successes, test_states, commands)
    except ValueError as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    print((args.out / REPORT_MD).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
