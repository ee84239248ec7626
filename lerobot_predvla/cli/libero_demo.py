"""`predvla demo libero`: the main job end to end on the LIBERO simulator, offline (CPU by default).

Stages (each is skipped when its output already exists, so a killed run resumes):
1. scripted-expert demonstrations (`predvla demos`),
2. the frozen front end's PCA bases (`predvla fit-frontend`),
3. conversion to a LeRobot dataset with cached features (`predvla convert`),
4. training with `lerobot-train --policy.type=predvla`,
5. evaluation with `lerobot-eval --env.type=predvla_libero` from the official init states, once with
   error regression and once in exact open loop (`--policy.er_iterations=0`),
6. the same evaluation of the shipped libero_object suite checkpoint (`checkpoints/predvla_libero_object`, one
   network for all ten tasks) on two tasks whose instructions ask for different objects: a blind replay of one
   demonstration cannot succeed on both,
7. per-task success tables, `results.json` and bar plots.
"""

import argparse
import os
import subprocess
import time
from pathlib import Path

from lerobot_predvla.cli.demos import task_ids
from lerobot_predvla.lerobot_commands import PREDVLA, eval_command, policy_args, train_command
from lerobot_predvla.sims.libero.protocol import EVAL_ENV_TYPE
from lerobot_predvla.sweep.eval_info import EVAL_INFO_FILE, success_rates
from lerobot_predvla.utils.checkpoints import last_pretrained
from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json

BANNER = "=" * 78
MODES = {"error regression": 10, "open loop": 0}  # er_iterations
SUITE_CHECKPOINT = Path("checkpoints/predvla_libero_object")  # trained on all ten libero_object tasks


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("libero", help="demos -> front end -> convert -> train -> eval on LIBERO",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("outputs/libero_demo"), help="output directory")
    p.add_argument("--suite", default="libero_object", help="LIBERO suite")
    p.add_argument("--tasks", type=task_ids, default=[0],
                   help="task ids, e.g. 0,1 (default: task 0, the measured default; see the README)")
    p.add_argument("--per-task", type=int, default=15, help="expert demonstrations per task")
    p.add_argument("--vision-weights", default="random",
                   help="ResNet18 weights for the front end: 'imagenet' (the paper's; needs the torchvision "
                   "download), a .pth file, or 'random' (default here: the download site is unreachable offline)")
    p.add_argument("--steps", type=int, default=4000,
                   help="lerobot-train steps (4,000: the open-loop prior learns the gripper release; 2,000 does not)")
    p.add_argument("--batch-size", type=int, default=8, help="lerobot-train batch size (episodes)")
    p.add_argument("--lr", type=float, default=1e-3, help="network learning rate (paper: 6e-5 over 30,000 steps)")
    p.add_argument("--episodes", type=int, default=10, help="evaluation episodes per task and mode")
    p.add_argument("--eval-batch-size", type=int, default=10, help="parallel environments during evaluation")
    p.add_argument("--episode-length", type=int, default=None, help="step cap (paper: 600; default: suite cap)")
    p.add_argument("--suite-checkpoint", default=str(SUITE_CHECKPOINT),
                   help="suite checkpoint evaluated in stage 6 ('none' skips the stage)")
    p.add_argument("--suite-tasks", type=task_ids, default=[0, 7], help="its tasks (default 0,7)")
    p.add_argument("--suite-episodes", type=int, default=5, help="its evaluation episodes per task and mode")
    p.add_argument("--device", default="cpu",
                   help="torch device for lerobot-train and lerobot-eval (--policy.device), e.g. cuda; default cpu")
    p.set_defaults(func=run)


def _run(stage: str, cmd: list[str]) -> None:
    print(f"\n{BANNER}\n{stage}\n$ {' '.join(cmd)}\n{BANNER}", flush=True)
    start = time.time()
    # One intra-op thread unless the user chose: PredVLA's recurrence is many small matmuls, and spinning
    # OpenMP threads on oversubscribed cores made a training step 10x slower (15 s vs 1.4 s, batch 8).
    env = {"OMP_NUM_THREADS": "1", **os.environ, "HF_HUB_OFFLINE": "1"}
    subprocess.run(cmd, check=True, env=env)
    print(f"[{stage}] done in {time.time() - start:.0f} s", flush=True)


def _skip(stage: str, path: Path) -> None:
    print(f"\n[{stage}] {path} exists: skipped (delete it to redo this stage)", flush=True)


def plot_success(results: dict[str, dict[int, float]], suite: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = sorted(next(iter(results.values())))
    width = 0.8 / len(results)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.5 + 1.2 * len(tasks)), 3.5))
    for i, (mode, success) in enumerate(results.items()):
        bars = ax.bar([t + i * width for t in range(len(tasks))], [success[t] for t in tasks], width, label=mode)
        ax.bar_label(bars, fmt="%.0f%%", fontsize=8)  # a 0% bar is otherwise invisible
    ax.set_xticks([t + width * (len(results) - 1) / 2 for t in range(len(tasks))], [f"task {t}" for t in tasks])
    ax.set(ylabel="success (%)", ylim=(0, 105))
    ax.set_title(f"PredVLA on {suite} (official init states)", fontsize=10)
    ax.legend()
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=120)


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    hdf5, frontend, dataset, train = out / "hdf5", out / "frontend", out / "dataset", out / "train"
    checkpoint = last_pretrained(train)
    tasks = ",".join(map(str, args.tasks))
    if args.vision_weights == "random":
        print(f"{BANNER}\nOFFLINE SUBSTITUTE: the front end uses a seeded random ResNet18 (--vision-weights random),"
              f"\nnot the paper's ImageNet weights, which download from the unreachable PyTorch site.\n{BANNER}")

    task_files = sorted((hdf5 / args.suite).glob("*_demo.hdf5"))
    if len(task_files) >= len(args.tasks):
        _skip("1/7 demonstrations", hdf5 / args.suite)
    else:
        _run("1/7 demonstrations", [*PREDVLA, "demos", "--suite", args.suite, "--tasks", tasks,
                                    "--per-task", str(args.per_task), "--render-interval", "4", "--out", str(hdf5)])
    if frontend.exists():
        _skip("2/7 front end", frontend)
    else:
        _run("2/7 front end", [*PREDVLA, "fit-frontend", "--hdf5-root", str(hdf5), "--suites", args.suite,
                               "--vision-weights", args.vision_weights, "--frame-stride", "4",
                               "--out", str(frontend)])  # PCA on the rendered frames (every 4th)
    if dataset.exists():
        _skip("3/7 conversion", dataset)
    else:
        _run("3/7 conversion", [*PREDVLA, "convert", "--hdf5-root", str(hdf5), "--suite", args.suite,
                                "--frontend", str(frontend), "--out", str(dataset),
                                "--repo-id", "local/predvla_libero_demo"])
    if checkpoint.exists():
        _skip("4/7 training", checkpoint)
    else:
        _run("4/7 training", train_command(
            policy=policy_args("predvla", {"optimizer_lr": args.lr}), dataset_repo_id="local/predvla_libero_demo",
            dataset_root=dataset, output_dir=train, steps=args.steps, batch_size=args.batch_size,
            save_freq=args.steps, device=args.device, extra=["--num_workers=0", "--log_freq=50"],
        ))
    results = evaluate(args, "5/7 evaluation", checkpoint, args.tasks, args.episodes, out / "eval")
    suite_results = None
    if args.suite_checkpoint == "none":
        print("\n[6/7 suite checkpoint] skipped (--suite-checkpoint none)")
    elif not Path(args.suite_checkpoint, "config.json").is_file():
        print(f"\n[6/7 suite checkpoint] {args.suite_checkpoint}/config.json not found: skipped (run from the "
              "repository root, or pass --suite-checkpoint)")
    else:
        suite_results = evaluate(args, "6/7 suite checkpoint", Path(args.suite_checkpoint), args.suite_tasks,
                                 args.suite_episodes, out / "suite_checkpoint_eval")
    summary = {"suite": args.suite, "episodes_per_task": args.episodes, "per_task": results,
               "mean": report("7/7 success of this training", args.suite, args.episodes, results)}
    plot_success(results, args.suite, out / "success.png")
    if suite_results is not None:
        summary["suite_checkpoint"] = {
            "path": args.suite_checkpoint, "episodes_per_task": args.suite_episodes, "per_task": suite_results,
            "mean": report(f"7/7 success of the suite checkpoint {args.suite_checkpoint}", args.suite,
                           args.suite_episodes, suite_results)}
        plot_success(suite_results, f"{args.suite}, suite checkpoint", out / "success_suite_checkpoint.png")
    atomic_write_json(out / "results.json", summary)
    print(f"results: {out / 'results.json'}\nplots: {out / 'success.png'}"
          + ("" if suite_results is None else f", {out / 'success_suite_checkpoint.png'}") + f"\n{BANNER}")
    return 0


def evaluate(args: argparse.Namespace, stage: str, checkpoint: Path, tasks: list[int], episodes: int,
             prefix: Path) -> dict[str, dict[int, float]]:
    """`lerobot-eval` with error regression and in exact open loop; per-task success rates per mode. Exact open
    loop never reads an observation, so its cameras are rendered only at reset (same actions, physics-only cost)."""
    results: dict[str, dict[int, float]] = {}
    task_list = ",".join(map(str, tasks))
    for mode, iterations in MODES.items():
        eval_dir = prefix.with_name(f"{prefix.name}_er{iterations}")
        info = eval_dir / EVAL_INFO_FILE
        if info.exists():
            _skip(f"{stage} ({mode})", info)
        else:
            sparse = ["--env.render_interval=100000"] if iterations == 0 else []
            _run(f"{stage} ({mode})", eval_command(
                checkpoint=checkpoint, device=args.device, policy=[f"--policy.er_iterations={iterations}"],
                env_type=EVAL_ENV_TYPE, suite=args.suite, episode_length=args.episode_length, n_episodes=episodes,
                batch_size=min(args.eval_batch_size, episodes), output_dir=eval_dir,
                extra=[f"--env.task_ids=[{task_list}]", *sparse],
            ))
        results[mode] = success_rates(info)
    return results


def report(title: str, suite: str, episodes: int, results: dict[str, dict[int, float]]) -> dict[str, float]:
    """Print a per-task success table; return the mean per mode."""
    print(f"\n{BANNER}\n{title} on {suite} ({episodes} episodes per task, official init states)")
    print(f"{'task':<8}" + "".join(f"{mode:>20}" for mode in results))
    for task in sorted(results["error regression"]):
        print(f"{task:<8}" + "".join(f"{results[mode][task]:>19.0f}%" for mode in results))
    means = {mode: sum(s.values()) / len(s) for mode, s in results.items()}
    print(f"{'mean':<8}" + "".join(f"{means[mode]:>19.1f}%" for mode in results))
    return means
