"""Where a real `lerobot-train` of PredVLA spends its time: arms side by side in one run.

Each arm is a real `lerobot-train` (through `benchmarks.lerobot_train_timed`, which times every loop iteration) on
one dataset, for `--steps` steps; the first `--warmup` iterations are dropped and the median iteration is reported,
with `lerobot-train`'s own `updt_s` (the update alone, mean of its log windows). Arms differ in one thing each from
`ddp2x16`, the layout full-scale trainings have used (two DDP processes of batch 16, one thread each, Table 2's
shape: sequences of 200 steps, 500 episodes of 132-150 steps):

| arm | what differs |
|---|---|
| `ddp2x16` | nothing (recipe `--recipe`, default `fit_sensory_olt`) |
| `1x32_1thread`, `1x32_2threads` | one process of batch 32, one or two intra-op threads |
| `ddp2x16_untrimmed` | the recurrence also runs over the batch's padding |
| `ddp2x16_unshared` | the action term's chain rolled out a second time (before the shared chain) |
| `ddp2x16_ckpt50` | a checkpoint (weights, optimizer, posteriors) every 50 steps instead of none |
| `ddp2x16_table2` | Table 2's literal recipe (one chain per step) instead of `--recipe` |
| `ddp2x16_bf16` | `--policy.use_amp=true` (bfloat16 loops; only with `--arms`) |

Then, in this process on one thread, the policy's own training step at batch 16 (forward, backward, both Adams)
without `lerobot-train`: `ddp2x16_over_fast_step` is what LeRobot's loop and DDP add to it.

Without `--dataset-root` a synthetic dataset of Table 2's shape (`predvla synthetic`'s columns; 10 tasks x 50
episodes of 132-150 frames) is written under `--work`; pass the features-only copy of a real dataset
(`predvla features-only`) to profile on it. Run on otherwise idle cores:

    python -m benchmarks.profile_lerobot_train --out benchmarks/results/profile_lerobot_train.json
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

from lerobot_predvla import lerobot_commands

RECIPES = {
    "table2": {},
    "fit_sensory_olt": {"posteriors_fit_actions": False, "open_loop_weight": 1.0},
}
ARMS = {
    # name: (processes, threads per process, recipe or None for --recipe, save_freq or None, patches, policy fields)
    "ddp2x16": (2, 1, None, None, "", {}),
    "1x32_1thread": (1, 1, None, None, "", {}),
    "1x32_2threads": (1, 2, None, None, "", {}),
    "ddp2x16_untrimmed": (2, 1, None, None, "untrimmed", {}),
    "ddp2x16_unshared": (2, 1, None, None, "unshared", {}),
    "ddp2x16_ckpt50": (2, 1, None, 50, "", {}),
    "ddp2x16_table2": (2, 1, "table2", None, "", {}),
    "ddp2x16_bf16": (2, 1, None, None, "", {"use_amp": True}),
}
DEFAULT_ARMS = [name for name in ARMS if name != "ddp2x16_bf16"]  # bfloat16 is opt-in: measured on request
UPDATE_S = re.compile(r"updt_s:([0-9.]+)")  # lerobot-train's log line: the update alone, its window's mean
BATCH, SEQUENCE_LENGTH, EPISODE_LENGTHS, TASKS, EPISODES_PER_TASK = 32, 200, (132, 150), 10, 50


def synthetic_dataset(root: Path) -> Path:
    """A dataset of Table 2's shape under `root` (made once)."""
    if not (root / "meta" / "info.json").is_file():
        from lerobot_predvla.data.synthetic import make_synthetic_dataset

        make_synthetic_dataset(root, repo_id="local/predvla_profile", num_tasks=TASKS,
                               episodes_per_task=EPISODES_PER_TASK, min_length=EPISODE_LENGTHS[0],
                               max_length=EPISODE_LENGTHS[1])
    return root


def arm_command(name: str, dataset: Path, work: Path, steps: int, recipe: str) -> tuple[list[str], dict]:
    processes, threads, arm_recipe, save_freq, patches, fields = ARMS[name]
    module = ["-m", "benchmarks.lerobot_train_timed"]
    program = ([lerobot_commands.TORCHRUN, f"--nproc_per_node={processes}", *module] if processes > 1
               else [sys.executable, *module])
    fields = {**RECIPES[arm_recipe or recipe], "sequence_length": SEQUENCE_LENGTH, **fields}
    command = lerobot_commands.train_command(
        program=program, policy=lerobot_commands.policy_args("predvla", fields), dataset_repo_id="local/profile",
        dataset_root=dataset, output_dir=work / "runs" / name, steps=steps, batch_size=BATCH // processes,
        save_freq=save_freq or steps * 10, device="cpu", seed=0,
        extra=["--num_workers=0", "--log_freq=25", f"--save_checkpoint={'true' if save_freq else 'false'}"],
    )
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "PREDVLA_PATCHES": patches,
           "PREDVLA_TIMES_OUT": str(work / "times" / name), "HF_HUB_OFFLINE": "1"}
    return command, env


def run_arm(name: str, dataset: Path, work: Path, steps: int, warmup: int, recipe: str) -> dict:
    command, env = arm_command(name, dataset, work, steps, recipe)
    (work / "times").mkdir(parents=True, exist_ok=True)
    log = work / "logs" / f"{name}.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with log.open("w") as f:
        code = subprocess.run(command, env=env, stdout=f, stderr=subprocess.STDOUT).returncode
    if code != 0:
        raise SystemExit(f"arm {name} failed (exit {code}); see {log}")
    times = json.loads((work / "times" / f"{name}.rank0.json").read_text())
    iterations = [b - a for a, b in zip(times, times[1:], strict=False)][warmup:]
    updt = [float(v) for v in UPDATE_S.findall(log.read_text())]
    return {"iteration_s_median": round(statistics.median(iterations), 4), "iterations": len(iterations),
            "updt_s_median": round(statistics.median(updt), 4) if updt else None,
            "wall_s": round(time.monotonic() - start, 1), "command": command}


def fast_step_s(dataset: Path, recipe: str, batch: int, repeats: int = 15) -> float:
    """The policy's own training step without `lerobot-train` (forward of Eq. 10 on `batch` episodes of `dataset`,
    backward, the network's Adam, the posteriors' `update`), one thread: the median of `repeats` after a warm-up."""
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

    torch.set_num_threads(1)
    config = PredVLAConfig(device="cpu", sequence_length=SEQUENCE_LENGTH, push_to_hub=False, **RECIPES[recipe])
    policy = make_policy(config, ds_meta=LeRobotDatasetMetadata("local/profile", root=dataset)).train()
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=config.optimizer_lr)
    episodes = torch.Generator().manual_seed(0)
    times = []
    for i in range(repeats + 1):
        index = torch.randint(policy.posterior_store.num_episodes, (batch,), generator=episodes)
        start = time.perf_counter()
        loss, _ = policy.forward({"episode_index": index})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        policy.update()
        if i:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset-root", type=Path, help="a features-only dataset (default: synthetic, Table 2 shape)")
    parser.add_argument("--work", type=Path, default=Path("outputs/profile_lerobot_train"))
    parser.add_argument("--steps", type=int, default=200, help="steps per arm (below 1,000: exact log step counts)")
    parser.add_argument("--warmup", type=int, default=20, help="iterations dropped at the start of each arm")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="fit_sensory_olt")
    parser.add_argument("--arms", default=",".join(DEFAULT_ARMS), help=f"comma-separated, of {', '.join(ARMS)}")
    parser.add_argument("--out", type=Path, help="write the JSON result here too")
    args = parser.parse_args()
    arms = args.arms.split(",")
    if unknown := sorted(set(arms) - set(ARMS)):
        raise SystemExit(f"--arms: unknown {unknown}; expected some of {', '.join(ARMS)}.")
    if args.work.exists() and any((args.work / "runs").glob("*")):
        raise SystemExit(f"--work {args.work} holds earlier runs: remove {args.work / 'runs'} first.")
    dataset = args.dataset_root or synthetic_dataset(args.work / "dataset")
    results = {}
    for name in arms:
        results[name] = run_arm(name, dataset, args.work, args.steps, args.warmup, args.recipe)
        print(f"{name}: {results[name]['iteration_s_median']:.3f} s per iteration "
              f"(updt_s {results[name]['updt_s_median']})", file=sys.stderr, flush=True)
    base = results.get("ddp2x16", {}).get("iteration_s_median")
    fast = fast_step_s(dataset, args.recipe, BATCH // 2) if base else None
    summary = {"recipe": args.recipe, "dataset": str(dataset), "steps": args.steps, "warmup": args.warmup,
               # lerobot-train's iteration (DDP rank 0, batch 16, one thread) over the policy's own step at batch 16
               # on one thread: what LeRobot's loop and DDP add (target <= 1.15)
               "fast_step_s_batch16": round(fast, 4) if fast else None,
               "ddp2x16_over_fast_step": round(base / fast, 3) if base else None,
               "arms": {n: {**r, **({"over_ddp2x16": round(r["iteration_s_median"] / base, 3)} if base else {})}
                        for n, r in results.items()}}
    text = json.dumps(summary, indent=1)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
