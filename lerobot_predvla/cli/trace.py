"""`predvla trace`: `lerobot-eval` of a PredVLA checkpoint with error regression traced step by step.

Every argument after OUT goes to lerobot-eval unchanged (its `--output_dir` defaults to OUT/eval). Writes
OUT/trace.json (the lerobot-eval arguments, OMP_NUM_THREADS as set or null, and, per episode in lerobot-eval's
order, per control step: the action, the prior chain's action and how far error regression moved each module's
posteriors, with the prediction errors the step observed before and after its iterations) and OUT/trace.png (episode
--episode of this run, beside the same episode of every --compare trace). With error regression it also writes
OUT/corrections.png (each module's move against the prediction error observed before the step, every step of every
episode, succeeded and failed episodes apart) and trace.json's `correlations` (Spearman per module and error).
lerobot-eval steps every environment of a batch until the last one ends, so an episode's trace runs past its own
end; eval_info.json in the output directory says which episodes succeeded. Example (seed 1 against seed 0 of
the same recipe, one reset):

  predvla trace outputs/trace_seed0 --policy.path=checkpoints/predvla_libero_object_lambda_q100 \\
    --policy.device=cpu --env.type=predvla_libero --env.task=libero_object '--env.task_ids=[7]' \\
    --env.episode_length=280 --env.init_states=false --seed=1000 --eval.n_episodes=2 --eval.batch_size=2
  predvla trace --episode 1 --compare outputs/trace_seed0 outputs/trace_seed1 \\
    --policy.path=checkpoints/predvla_libero_object_lambda_q100_seed1 ...(the same arguments)
"""

import argparse
import json
import os
import sys
from pathlib import Path

from lerobot_predvla.policies.predvla.error_regression import ErrorRegression
from lerobot_predvla.policies.predvla.trace import TraceRecorder, correlations, plot_corrections, plot_traces
from lerobot_predvla.sweep.eval_info import EVAL_INFO_FILE, EvalInfoError, episode_successes
from lerobot_predvla.utils.io import atomic_write_json

TRACE_FILE = "trace.json"
FIGURE_FILE = "trace.png"
CORRECTIONS_FILE = "corrections.png"


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("trace", help="lerobot-eval with error regression traced per step, and a plot",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episode", type=int, default=0, help="episode drawn in trace.png (lerobot-eval's order)")
    p.add_argument("--compare", type=Path, action="append", default=[], metavar="DIR",
                   help="OUT of an earlier trace to draw beside this one (repeatable)")
    p.add_argument("out", type=Path, help="output directory (trace.json, trace.png, eval/)")
    p.add_argument("eval_args", nargs=argparse.REMAINDER, help="lerobot-eval arguments (--policy.path=... etc.)")
    p.set_defaults(func=run)


def load_trace(directory: Path) -> dict:
    path = directory / TRACE_FILE
    try:
        trace = json.loads(path.read_text())
        if not isinstance(trace.get("episodes"), list):
            raise ValueError("no list of episodes")
    except (OSError, ValueError, AttributeError) as err:
        raise ValueError(f"--compare {directory}: expected a trace of `predvla trace` at {path} ({err}).") from err
    return trace


def run(args: argparse.Namespace) -> int:
    try:
        if args.episode < 0:
            raise ValueError(f"--episode must be >= 0, got {args.episode}.")
        if not any(a.startswith("--policy.path") for a in args.eval_args):
            raise ValueError("lerobot-eval needs --policy.path=CHECKPOINT after OUT.")
        compared = {d.name: load_trace(d) for d in args.compare}
        for name, other in compared.items():
            if args.episode >= len(other["episodes"]):
                raise ValueError(f"--episode {args.episode}: --compare {name} has {len(other['episodes'])} episodes.")
    except ValueError as err:
        print(f"predvla trace: error: {err}", file=sys.stderr)
        return 2
    from lerobot.scripts.lerobot_eval import main as lerobot_eval

    eval_args = list(args.eval_args)
    if not any(a.startswith("--output_dir") for a in eval_args):
        eval_args.append(f"--output_dir={args.out / 'eval'}")
    recorder, argv = TraceRecorder(), sys.argv
    ErrorRegression.tracer, sys.argv = recorder, ["lerobot-eval", *eval_args]
    try:
        lerobot_eval()
    except SystemExit as exit_:
        if exit_.code:
            print(f"predvla trace: lerobot-eval stopped (exit {exit_.code}); nothing written", file=sys.stderr)
            return int(exit_.code) if isinstance(exit_.code, int) else 2
    finally:
        ErrorRegression.tracer, sys.argv = None, argv
    episodes = recorder.episodes()
    if not episodes:
        print("predvla trace: error: no step of error regression was recorded; is --policy.path a PredVLA "
              "checkpoint?", file=sys.stderr)
        return 2
    # the thread count is part of the run: error regression's outcomes can turn on how its sums are rounded
    trace = {"eval_args": eval_args, "omp_num_threads": os.environ.get("OMP_NUM_THREADS"), "episodes": episodes}
    traced_er = any("error_before" in ep for ep in episodes)
    if traced_er:
        trace["correlations"] = correlations(episodes)
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / TRACE_FILE, trace)
    if traced_er:
        succeeded = run_successes(eval_args, len(episodes))
        plot_corrections(episodes, succeeded, args.out / CORRECTIONS_FILE,
                         f"{args.out.name}: posterior moves against the observed prediction error")
    if args.episode >= len(episodes):
        print(f"predvla trace: error: --episode {args.episode}, but lerobot-eval ran {len(episodes)} episodes "
              f"({args.out / TRACE_FILE} is written, no figure)", file=sys.stderr)
        return 2
    plot_traces({args.out.name: trace, **compared}, args.episode, args.out / FIGURE_FILE)
    written = [args.out / TRACE_FILE, args.out / FIGURE_FILE] + ([args.out / CORRECTIONS_FILE] if traced_er else [])
    print(f"predvla trace: {len(episodes)} episodes, up to {max(len(e['steps']) for e in episodes)} steps; "
          + ", ".join(map(str, written)))
    return 0


def run_successes(eval_args: list[str], n_episodes: int) -> list[bool] | None:
    """Success of each traced episode from the run's eval_info.json (tasks in lerobot-eval's order, ascending
    ids), or None when it cannot be read or does not hold exactly the traced episodes."""
    output_dir = next((a.split("=", 1)[1] for a in eval_args if a.startswith("--output_dir=")), None)
    if output_dir is None:
        return None
    try:
        successes = [ok for task in episode_successes(Path(output_dir) / EVAL_INFO_FILE).values() for ok in task]
    except EvalInfoError:
        return None
    return successes if len(successes) == n_episodes else None
