"""`predvla demo synthetic`: the offline end-to-end job on a generated dataset (no simulator).

Generates a small dataset with PredVLA's cached columns, trains with the real `lerobot-train`, then
replays held-in episodes through the checkpoint's processors and policy, once with error regression and
once in exact open loop, and reports the action error of each against the demonstrations.
"""

import argparse
import json
import os
import subprocess
from pathlib import Path

import torch
from tqdm import tqdm

from lerobot_predvla.data.synthetic import make_synthetic_dataset
from lerobot_predvla.lerobot_commands import policy_args, train_command
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy
from lerobot_predvla.utils.checkpoints import last_pretrained
from lerobot_predvla.utils.io import atomic_save_figure

BANNER = "=" * 78


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("synthetic", help="train and replay PredVLA on a generated dataset")
    p.add_argument("--out", type=Path, default=Path("outputs/synthetic_demo"), help="output directory")
    p.add_argument("--steps", type=int, default=300, help="lerobot-train steps")
    p.add_argument("--batch-size", type=int, default=8)
    p.add_argument("--episodes", type=int, default=2, help="episodes replayed per mode")
    p.add_argument("--device", default="cpu", help="torch device for training and replay, e.g. cuda; default cpu")
    p.set_defaults(func=run)


def replay(
    checkpoint: Path, dataset_root: Path, episodes: int, er_iterations: int, device: str
) -> tuple[float, list]:
    """Mean squared action error over replayed episodes and the first episode's actions."""
    from lerobot.datasets import LeRobotDataset
    from lerobot.policies.factory import make_pre_post_processors

    config = PredVLAConfig.from_pretrained(checkpoint)
    config.er_iterations, config.device = er_iterations, device
    policy = PredVLAPolicy.from_pretrained(checkpoint, config=config)
    pre, post = make_pre_post_processors(
        config, pretrained_path=str(checkpoint), preprocessor_overrides={"device_processor": {"device": device}}
    )
    dataset = LeRobotDataset("local/predvla_synthetic", root=dataset_root)
    errors, first = [], []
    bounds = dataset.meta.episodes
    for ep in range(episodes):
        policy.reset()
        start, stop = bounds["dataset_from_index"][ep], bounds["dataset_to_index"][ep]
        for i in tqdm(range(start, stop), desc=f"replay ep {ep} (er_iterations={er_iterations})", leave=False):
            frame = dataset[i]
            with torch.inference_mode():
                action = post(policy.select_action(pre(dict(frame))))[0]
            errors.append(((action - frame["action"]) ** 2).mean().item())  # both on the CPU (postprocessor)
            if ep == 0:
                first.append((action[0].item(), frame["action"][0].item()))
    return sum(errors) / len(errors), first


def run(args: argparse.Namespace) -> int:
    print(f"{BANNER}\nSYNTHETIC DEMO: a generated dataset stands in for LIBERO (no simulator involved).\n{BANNER}")
    out: Path = args.out
    dataset_root, train_dir = out / "dataset", out / "train"
    if not dataset_root.exists():
        make_synthetic_dataset(dataset_root, num_tasks=2, episodes_per_task=6)
    checkpoint = last_pretrained(train_dir)
    if not checkpoint.exists():
        cmd = train_command(
            policy=policy_args("predvla", {"sequence_length": 64, "optimizer_lr": 1e-3}),
            dataset_repo_id="local/predvla_synthetic", dataset_root=dataset_root, output_dir=train_dir,
            steps=args.steps, batch_size=args.batch_size, save_freq=args.steps, device=args.device,
            extra=["--num_workers=0", "--log_freq=25"],
        )
        print("$", " ".join(cmd), flush=True)
        subprocess.run(cmd, check=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    results = {}
    for iterations in (10, 0):
        mse, first = replay(checkpoint, dataset_root, args.episodes, iterations, args.device)
        results[iterations] = {"action_mse": mse, "first_episode": first}
    print(f"\n{'mode':<34}{'action MSE vs demonstrations':>30}")
    print(f"{'error regression (10 iterations)':<34}{results[10]['action_mse']:>30.5f}")
    print(f"{'exact open loop (0 iterations)':<34}{results[0]['action_mse']:>30.5f}")
    plot = out / "synthetic_demo.png"
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot([d for _, d in results[10]["first_episode"]], "k", label="demonstration")
    ax.plot([a for a, _ in results[10]["first_episode"]], label="error regression")
    ax.plot([a for a, _ in results[0]["first_episode"]], "--", label="open loop")
    ax.set(xlabel="control step", ylabel="action[0]", title="PredVLA on the synthetic dataset, episode 0")
    ax.legend()
    fig.tight_layout()
    atomic_save_figure(fig, plot, dpi=120)
    (out / "results.json").write_text(json.dumps({k: v["action_mse"] for k, v in results.items()}, indent=2))
    print(f"plot: {plot}\nresults: {out / 'results.json'}")
    return 0
