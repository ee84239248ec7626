"""What error regression's correction answers to: its departure from the exact open loop before the grasp, start by
start, against how the scripted expert's own approach varies over the same starts.

Exact open loop never reads an observation, so on every official init state of a task it commands one sequence of
actions. Error regression (a `predvla trace` of the same checkpoint) departs from it as the observations move its
posteriors. Before the grasp, that departure has one job: the objects (and the arm's start) differ by millimetres
between the official init states, and the hand must end over the object. The scripted expert, which reads the
simulator, shows how much each start asks for. Per task and official init state s, over the x, y actions (OSC
position deltas, world frame; the same controller for all three, so summed actions compare as commanded hand
displacements):

  E_s   the expert's summed x, y actions until it closes the gripper, from start s;
  R_s   error regression's, until its own gripper closes;
  O     the exact open loop's, the same on every start.

The expert's deviation E_s - mean(E) is what start s asks beyond the average start; error regression's correction
R_s - O is what it did. If error regression steers with its observations, the correction tracks the deviation (slope
near 1, R^2 near 1, pooled over tasks after centring each task); a correction whose mean over starts is large and
whose spread is small is a bias shared by every start, which no observation explains.

Command (from the repository root):

  predvla trace OUT/er_task7 --policy.path=CKPT --env.type=predvla_libero --env.task=libero_object \\
      '--env.task_ids=[7]' --env.init_states=true --eval.n_episodes=10 --eval.batch_size=1 ...
  predvla trace OUT/ol_task7 --policy.path=CKPT ... --eval.n_episodes=1 --policy.er_iterations=0
  python -m research.er_correction --trace OUT/er_task7 --open-loop OUT/ol_task7 --out OUT

Each --trace pairs with the --open-loop of its task (one episode suffices: exact open loop reads no observation).
Runs the scripted expert from the same official init states (physics only, seconds per start), then writes
OUT/correction.json, correction.md and correction.png.
"""

import argparse
import json
import re
import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from scipy import stats

from lerobot_predvla.policies.predvla.diagnostics import gripper_events
from lerobot_predvla.sims.libero.env import make_env, official_init_states, task_spec
from lerobot_predvla.sims.libero.protocol import PAPER_EPISODE_LENGTH
from lerobot_predvla.sims.libero.rollout import run_episode
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json, atomic_write_text
from research.postprocessor import POSTPROCESSOR_FILE, load_postprocessor

XY = slice(0, 2)  # the OSC position deltas that place the hand over the object
REPORT_JSON, REPORT_MD, FIGURE = "correction.json", "correction.md", "correction.png"
COMMAND = "python -m research.er_correction"
INTRO = ("Per task and official init state s, summed x, y actions (OSC position deltas; one controller, so the sums "
         "compare as commanded hand displacements): E_s, the scripted expert's until it closes the gripper; R_s, "
         "error regression's until its own gripper closes; O, the exact open loop's, the same on every start. "
         "Error regression's correction R_s - O should follow the expert's deviation E_s - mean E (slope 1); a "
         "correction with a large mean and a small spread over the starts is a bias they share, which no "
         "observation explains. Per start: correction.json.")


def close_step(actions: np.ndarray) -> int | None:
    """First step whose gripper command closes (`gripper_events`), or None if the gripper never closes."""
    steps = len(actions)
    close = gripper_events(torch.as_tensor(actions)[:, None], torch.ones(steps, 1, dtype=torch.bool))[0, 0]
    return None if close.isnan() else int(close)


def approach(actions: np.ndarray) -> tuple[np.ndarray, int | None]:
    """Summed x, y actions before the gripper first closes (the whole sequence if it never does), and that step."""
    step = close_step(actions)
    return np.asarray(actions)[:step, XY].sum(axis=0), step


@dataclass
class TraceRun:
    """One `predvla trace` directory: its task, its episodes' raw actions (episode i is official init state i, or
    the i-th randomised reset of its seed)."""

    path: Path
    task_id: int
    checkpoint: str
    open_loop: bool
    actions: list[np.ndarray]
    eval_args: list[str]
    omp_num_threads: str | None = None  # as the trace ran (None: not set, or a trace that predates the field)

    @property
    def output_dir(self) -> Path:
        """lerobot-eval's output directory of the trace (its eval_info.json)."""
        return Path(_arg(self.eval_args, "output_dir") or self.path / "eval")

    @property
    def official_states(self) -> bool:
        """Whether the episodes start from the official init states (else from randomised resets)."""
        return _arg(self.eval_args, "env.init_states") == "true"

    @property
    def seed(self) -> str | None:
        """lerobot-eval's --seed of the trace (None: its default)."""
        return _arg(self.eval_args, "seed")

    def command(self) -> str:
        """The `predvla trace` command that made this directory (its output directory left to the default)."""
        kept = [a for a in self.eval_args if not a.startswith("--output_dir=")]
        threads = f"OMP_NUM_THREADS={self.omp_num_threads} " if self.omp_num_threads is not None else ""
        return f"{threads}predvla trace {self.path} {shlex.join(kept)}"


def _arg(eval_args: list[str], name: str) -> str | None:
    for arg in eval_args:
        if arg.startswith(f"--{name}="):
            return arg.split("=", 1)[1]
    return None


def load_trace_run(directory: Path, official_states: bool = True) -> TraceRun:
    """Read a trace of one task (one `--env.task_ids`) on the official init states (`--env.init_states=true`; with
    `official_states=False` also on randomised resets), and turn its actions into raw units with the checkpoint's
    own postprocessor (as lerobot-eval does)."""
    path = Path(directory) / "trace.json"
    try:
        trace = json.loads(path.read_text())
        eval_args, episodes = trace["eval_args"], trace["episodes"]
    except (OSError, ValueError, KeyError) as err:
        raise ValueError(f"{path}: expected the trace.json of `predvla trace` ({err}).") from err
    task_ids = re.findall(r"\d+", _arg(eval_args, "env.task_ids") or "")
    if len(task_ids) != 1 or (official_states and _arg(eval_args, "env.init_states") != "true"):
        starts = " on the official init states (--env.init_states=true)" if official_states else ""
        raise ValueError(f"{path}: expected a trace of one task (--env.task_ids=[K]){starts}; its arguments are "
                         f"{eval_args}.")
    checkpoint = _arg(eval_args, "policy.path")
    if checkpoint is None or not (Path(checkpoint) / POSTPROCESSOR_FILE).is_file():
        raise ValueError(f"{path}: its --policy.path ({checkpoint}) has no {POSTPROCESSOR_FILE}.")
    postprocessor = load_postprocessor(Path(checkpoint))
    with torch.no_grad():
        actions = [postprocessor(torch.tensor(e["action"])).double().numpy() for e in episodes]
    iterations = _arg(eval_args, "policy.er_iterations")
    return TraceRun(Path(directory), int(task_ids[0]), checkpoint, iterations == "0", actions, eval_args,
                    trace.get("omp_num_threads"))


def expert_approaches(suite: str, task_id: int, states: list[int], cap: int) -> list[dict]:
    """The scripted expert from each official init state (physics only): its summed x, y actions until it closes
    the gripper, that step, and whether it succeeded."""
    init_states = official_init_states(suite, task_id)
    env = make_env(task_spec(suite, task_id))
    try:
        rows = []
        for state in states:
            episode = run_episode(env, state, cap, init_state=init_states[state])
            total, step = approach(episode.actions)
            rows.append({"state": state, "sum_xy": total.tolist(), "close_step": step, "success": episode.success})
    finally:
        env.close()
    return rows


@dataclass
class TaskCorrection:
    """Per start: the expert's deviation from its mean approach, error regression's correction of the open loop."""

    task_id: int
    states: list[int]
    expert_deviation: list[list[float]]
    correction: list[list[float]]
    open_loop_offset: list[float]  # O - mean(E): where the open loop's approach sits against the expert's mean
    expert_close: list[int | None]
    er_close: list[int | None]
    open_loop_close: int | None


def task_correction(er: TraceRun, open_loop: TraceRun, expert: list[dict]) -> TaskCorrection:
    if er.task_id != open_loop.task_id:
        raise ValueError(f"{er.path} is task {er.task_id}, {open_loop.path} task {open_loop.task_id}.")
    states = list(range(len(er.actions)))
    by_state = {row["state"]: row for row in expert}
    missing = [s for s in states if s not in by_state]
    if missing:
        raise ValueError(f"task {er.task_id}: no expert approach for official init states {missing}.")
    expert_sum = np.array([by_state[s]["sum_xy"] for s in states])
    ol_sum, ol_close = approach(open_loop.actions[0])
    er_rows = [approach(a) for a in er.actions]
    return TaskCorrection(
        task_id=er.task_id, states=states,
        expert_deviation=(expert_sum - expert_sum.mean(axis=0)).tolist(),
        correction=[(total - ol_sum).tolist() for total, _ in er_rows],
        open_loop_offset=(ol_sum - expert_sum.mean(axis=0)).tolist(),
        expert_close=[by_state[s]["close_step"] for s in states], er_close=[step for _, step in er_rows],
        open_loop_close=ol_close,
    )


def summarise(tasks: list[TaskCorrection]) -> dict:
    """Per axis, pooled over tasks (each already centred on its own expert mean): the correction's regression on
    the expert's deviation, and per task the correction's mean against its spread and the deviation's spread."""
    deviation = np.concatenate([np.asarray(t.expert_deviation) for t in tasks])
    correction = np.concatenate([np.asarray(t.correction) for t in tasks])
    centred = np.concatenate([np.asarray(t.correction) - np.mean(t.correction, axis=0) for t in tasks])
    axes = {}
    for k, axis in enumerate("xy"):
        fit = stats.linregress(deviation[:, k], centred[:, k])
        axes[axis] = {"slope": float(fit.slope), "r2": float(fit.rvalue ** 2), "p": float(fit.pvalue),
                      "correction_rms": float(np.sqrt(np.mean(correction[:, k] ** 2)))}
    per_task = {}
    for t in tasks:
        c, d = np.asarray(t.correction), np.asarray(t.expert_deviation)
        fits = [stats.linregress(d[:, k], c[:, k]) for k in range(2)]
        per_task[str(t.task_id)] = {
            "correction_mean": c.mean(axis=0).tolist(), "correction_std": c.std(axis=0).tolist(),
            "expert_deviation_std": d.std(axis=0).tolist(), "open_loop_offset": t.open_loop_offset,
            "slope": [float(f.slope) for f in fits], "r": [float(f.rvalue) for f in fits],
            "p": [float(f.pvalue) for f in fits],
        }
    return {"axes": axes, "per_task": per_task, "episodes": int(len(deviation))}


def _vec(v: list[float]) -> str:
    return ", ".join(f"{x:+.3f}" for x in v)


def markdown(summary: dict, tasks: list[TaskCorrection], commands: list[str]) -> str:
    lines = ["# Error regression's correction before the grasp, against what each start asks", "", INTRO, "",
             "Reproduce:", "", "```bash", *commands, "```", "",
             f"Pooled over {summary['episodes']} episodes, each task centred (correction R_s - O regressed on the "
             "expert's deviation E_s - mean E, x and y, summed actions):", "",
             "| axis | slope | R^2 | p | correction, rms |", "|---|---|---|---|---|"]
    for axis, a in summary["axes"].items():
        lines.append(f"| {axis} | {a['slope']:.2f} | {a['r2']:.2f} | {a['p']:.2g} | {a['correction_rms']:.3f} |")
    lines += ["", "Per task (x, y): the correction's mean and spread over starts, the expert's spread, and where the "
              "open loop's approach sits against the expert's mean (O - mean E):", "",
              "| task | correction mean | correction std | expert deviation std | open loop - expert mean | "
              "slope (r, p) of the correction on the deviation, x; y | "
              "close step: open loop / error regression / expert (median) |", "|---|---|---|---|---|---|---|"]
    for t in tasks:
        s = summary["per_task"][str(t.task_id)]
        closes = [c for c in t.er_close if c is not None], [c for c in t.expert_close if c is not None]
        med = [f"{np.median(c):.0f}" if c else "never" for c in closes]
        fits = "; ".join(f"{m:+.2f} ({r:+.2f}, {p:.2g})" for m, r, p in zip(s["slope"], s["r"], s["p"], strict=True))
        lines.append(f"| {t.task_id} | {_vec(s['correction_mean'])} | {_vec(s['correction_std'])} | "
                     f"{_vec(s['expert_deviation_std'])} | {_vec(s['open_loop_offset'])} | {fits} | "
                     f"{t.open_loop_close} / {med[0]} / {med[1]} |")
    return "\n".join(lines) + "\n"


def figure(tasks: list[TaskCorrection], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    for k, (ax, axis) in enumerate(zip(axes, "xy", strict=True)):
        for t in tasks:
            ax.scatter(np.asarray(t.expert_deviation)[:, k], np.asarray(t.correction)[:, k], label=f"task {t.task_id}")
        low, high = ax.get_xlim()
        ax.plot([low, high], [low, high], "k--", lw=0.8, label="correction = deviation")
        ax.axhline(0, color="grey", lw=0.5)
        ax.set_xlabel(f"expert's deviation from its mean approach, {axis} (summed actions)")
        ax.set_ylabel(f"error regression - open loop, {axis} (summed actions)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Before the grasp: what error regression corrects against what each start asks")
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=90)
    plt.close(fig)


def write_report(out: Path, tasks: list[TaskCorrection], expert: dict[int, list[dict]],
                 commands: list[str]) -> dict:
    summary = summarise(tasks)
    out.mkdir(parents=True, exist_ok=True)
    report = {"summary": summary, "tasks": [asdict(t) for t in tasks],
              "expert": {str(k): v for k, v in expert.items()}, "commands": commands}
    atomic_write_json(out / REPORT_JSON, report)
    atomic_write_text(out / REPORT_MD, markdown(summary, tasks, commands))
    figure(tasks, out / FIGURE)
    return report


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=COMMAND, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--trace", type=Path, action="append", required=True, metavar="DIR",
                   help="`predvla trace` OUT of error regression on one task, official init states 0..n-1")
    p.add_argument("--open-loop", type=Path, action="append", required=True, metavar="DIR",
                   help="`predvla trace` OUT of the same checkpoint with --policy.er_iterations=0, same task")
    p.add_argument("--suite", default="libero_object")
    p.add_argument("--cap", type=int, default=PAPER_EPISODE_LENGTH, help="the expert's step cap")
    p.add_argument("--out", type=Path, required=True, help="directory for correction.json/.md/.png")
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
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
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    commands = [r.command() for r in [*ers, *open_loops.values()]]
    commands.append(f"{COMMAND} {shlex.join(argv)}")
    write_report(args.out, tasks, expert, commands)
    print((args.out / REPORT_MD).read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
