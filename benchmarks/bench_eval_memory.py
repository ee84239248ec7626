"""Peak memory of a LIBERO evaluation: the simulator's share (one environment, ten) and what `lerobot-eval` adds.

Every figure is the peak resident set (VmHWM, from `wait4`'s `ru_maxrss`) of one fresh process, in GB (1e9 bytes):

- imports: Python, torch, LeRobot's `lerobot_eval`, the plugin and LIBERO, no environment;
- N environments: imports + `--env.type=predvla_libero` environments of libero_object task 0, reset from their
  official init states and stepped `--steps` times with random actions (rendering as in an evaluation);
- `lerobot-eval` at batch N: the shipped checkpoint (`checkpoints/predvla_libero_object`, error regression) on
  the same task, `--eval.n_episodes=N --eval.batch_size=N --env.episode_length=<steps>`, sync environments.

"policy, front end and evaluation loop" is `lerobot-eval` at batch N minus N environments alone.

    python -m benchmarks.bench_eval_memory --steps 20      # the table, then one JSON line (about 6 min on 2 cores)

`predvla bench --quick` runs only the `lerobot-eval` measurement at batch 10 (`eval_peak_rss_gb`, `eval_peak_rss`).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
CHECKPOINT = REPOSITORY / "checkpoints" / "predvla_libero_object"
SUITE, TASK_ID = "libero_object", 0
EVAL_BATCH, EVAL_STEPS = 10, 20  # `eval_peak_rss_gb` of `predvla bench --quick`: batch 10, 20-step episodes
GB = 1e9


# Runs argv[2:] and writes its peak RSS (KiB) to argv[1]. A process started by fork keeps the peak of the memory it
# shared with its parent until exec (the kernel carries the pre-exec high-water mark into `ru_maxrss`), so a large
# caller, such as `predvla bench` after its other workloads, would report its own size: this small fresh interpreter
# starts the measured command instead, and only its own small size carries over.
_LAUNCHER = ("import os, subprocess, sys\n"
             "process = subprocess.Popen(sys.argv[2:])\n"
             "_, status, usage = os.wait4(process.pid, 0)\n"
             "open(sys.argv[1], 'w').write(str(usage.ru_maxrss))\n"
             "sys.exit(os.waitstatus_to_exitcode(status))\n")


def peak_rss_gb(command: list[str], log: Path) -> float:
    """Run `command` to completion (output to `log`) and return its peak resident set in GB.

    `wait4` reports the command's `ru_maxrss` (its VmHWM, or that of a descendant it waited for if larger): the
    exact peak, with no sampling interval to miss it. A small launcher process starts it (see `_LAUNCHER`)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
    peak_file = log.with_suffix(".maxrss")
    with log.open("w") as out:
        process = subprocess.run([sys.executable, "-c", _LAUNCHER, str(peak_file), *command], stdout=out,
                                 stderr=subprocess.STDOUT, env=env, cwd=REPOSITORY, check=False)
    if process.returncode != 0:
        tail = "\n".join(log.read_text(errors="replace").splitlines()[-20:])
        raise RuntimeError(f"{' '.join(command)} exited with {process.returncode}:\n{tail}")
    return int(peak_file.read_text()) * 1024 / GB  # ru_maxrss is in KiB on Linux


def lerobot_eval_command(batch: int, steps: int, output_dir: Path) -> list[str]:
    """`lerobot-eval` of the shipped checkpoint: `batch` episodes of `steps` steps on libero_object task 0."""
    return [str(Path(sys.executable).parent / "lerobot-eval"), f"--policy.path={CHECKPOINT}",
            "--env.type=predvla_libero", f"--env.task={SUITE}", f"--env.task_ids=[{TASK_ID}]",
            f"--env.episode_length={steps}", f"--eval.n_episodes={batch}", f"--eval.batch_size={batch}",
            "--eval.use_async_envs=false", f"--output_dir={output_dir}"]


def eval_peak_rss(batch: int = EVAL_BATCH, steps: int = EVAL_STEPS) -> dict:
    """Peak RSS of one `lerobot-eval` at `batch` (the `predvla bench` keys), or why it could not run."""
    if not CHECKPOINT.is_dir():
        return {"eval_peak_rss_gb": None, "eval_peak_rss": f"{CHECKPOINT} not found"}
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        try:
            peak = peak_rss_gb(lerobot_eval_command(batch, steps, Path(tmp) / "eval"), Path(tmp) / "eval.log")
        except RuntimeError as err:  # no simulator (`make libero`), no GL: the key says so instead of a number
            return {"eval_peak_rss_gb": None, "eval_peak_rss": str(err).splitlines()[-1]}
    return {"eval_peak_rss_gb": peak,
            "eval_peak_rss": f"lerobot-eval of {CHECKPOINT.name}, {SUITE} task {TASK_ID}, batch {batch}, "
                             f"{steps}-step episodes, sync envs ({time.perf_counter() - start:.0f} s)"}


def environments_only(n_envs: int, steps: int) -> None:
    """Imports as `lerobot-eval` has them, then `n_envs` environments reset and stepped (run in a child)."""
    import numpy as np
    from lerobot.scripts import lerobot_eval  # noqa: F401  (the imports lerobot-eval holds)

    from lerobot_predvla.sims.libero import predvla_libero  # noqa: F401  (LIBERO, robosuite, MuJoCo)
    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    if n_envs == 0:
        return
    cfg = PredVLALiberoEnv(task=SUITE, task_ids=[TASK_ID], episode_length=steps)
    venv = cfg.create_envs(n_envs=n_envs)[SUITE][TASK_ID]
    venv.reset(seed=list(range(n_envs)))
    rng = np.random.default_rng(0)
    for _ in range(steps):
        venv.step(rng.uniform(-0.3, 0.3, (n_envs, 7)).astype(np.float32))
    venv.close()


def measure_all(steps: int) -> dict:
    """Every row of docs/speed.md's memory table, each in a fresh process."""
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n_envs in (0, 1, EVAL_BATCH):
            command = [sys.executable, "-m", "benchmarks.bench_eval_memory", "--environments-only", str(n_envs),
                       "--steps", str(steps)]
            results[f"envs_{n_envs}_gb"] = peak_rss_gb(command, Path(tmp) / f"envs_{n_envs}.log")
        for batch in (1, EVAL_BATCH):
            command = lerobot_eval_command(batch, steps, Path(tmp) / f"eval_{batch}")
            results[f"lerobot_eval_b{batch}_gb"] = peak_rss_gb(command, Path(tmp) / f"eval_{batch}.log")
    results.update(
        steps=steps,
        simulator_per_env_gb=(results[f"envs_{EVAL_BATCH}_gb"] - results["envs_1_gb"]) / (EVAL_BATCH - 1),
        on_top_of_envs_b1_gb=results["lerobot_eval_b1_gb"] - results["envs_1_gb"],
        on_top_of_envs_b10_gb=results[f"lerobot_eval_b{EVAL_BATCH}_gb"] - results[f"envs_{EVAL_BATCH}_gb"],
    )
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=EVAL_STEPS, help="control steps per episode")
    parser.add_argument("--environments-only", type=int, metavar="N", help=argparse.SUPPRESS)  # the child
    args = parser.parse_args(argv)
    if args.environments_only is not None:
        environments_only(args.environments_only, args.steps)
        return 0
    results = measure_all(args.steps)
    print(f"peak RSS (GB), libero_object task {TASK_ID}, {args.steps} steps:")
    for key, label in (("envs_0_gb", "imports, no environment"), ("envs_1_gb", "one environment"),
                       (f"envs_{EVAL_BATCH}_gb", f"{EVAL_BATCH} environments"),
                       ("lerobot_eval_b1_gb", "lerobot-eval, batch 1"),
                       (f"lerobot_eval_b{EVAL_BATCH}_gb", f"lerobot-eval, batch {EVAL_BATCH}"),
                       ("simulator_per_env_gb", "each further environment"),
                       ("on_top_of_envs_b1_gb", "policy + front end + eval loop, batch 1"),
                       (f"on_top_of_envs_b{EVAL_BATCH}_gb", f"policy + front end + eval loop, batch {EVAL_BATCH}")):
        print(f"  {label:44s} {results[key]:6.2f}")
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
