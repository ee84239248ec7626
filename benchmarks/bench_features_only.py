"""A baseline's `lerobot-train` step on a converted dataset and on its copy without camera frames (`predvla
features-only`), paired in one run.

Both `DataLoader`s are LeRobot's (`make_train_eval_datasets`, `--num_workers=0`) with one shuffle seed, so each
round loads the same indices from both (checked: every non-camera value equal); the update is LeRobot's
`update_policy` on BC-Transformer (B1), the same for either batch because the policy reads no camera frame.
Reported: medians over rounds (warm-up excluded) of the batch load from each dataset and of the update, and the
step's ratio (load + update, original over copy).

    python -m benchmarks.bench_features_only --dataset-root outputs/libero_object_table2/dataset
"""

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import datasets
import torch
from accelerate import Accelerator
from lerobot.configs.default import DatasetConfig
from lerobot.configs.train import TrainPipelineConfig
from lerobot.optim.factory import make_optimizer_and_scheduler
from lerobot.policies import make_policy, make_pre_post_processors
from lerobot.scripts.lerobot_train import make_train_eval_datasets, update_policy
from lerobot.utils.logging_utils import AverageMeter, MetricsTracker

from lerobot_predvla.data.features_only import features_only_copy
from lerobot_predvla.policies.bc_transformer.configuration_predvla_bc_transformer import PredVLABCTransformerConfig


def loader(root: Path, batch: int, seed: int) -> tuple[TrainPipelineConfig, object, torch.utils.data.DataLoader]:
    """lerobot-train's dataset and DataLoader for B1 on `root`, shuffled from `seed`."""
    cfg = TrainPipelineConfig(
        dataset=DatasetConfig(repo_id="local/bench", root=str(root)), output_dir=root.parent / "unused",
        policy=PredVLABCTransformerConfig(device="cpu", push_to_hub=False), batch_size=batch, num_workers=0,
    )
    cfg.validate()
    dataset, _ = make_train_eval_datasets(cfg)
    generator = torch.Generator().manual_seed(seed)
    return cfg, dataset, torch.utils.data.DataLoader(dataset, batch_size=batch, shuffle=True, num_workers=0,
                                                     generator=generator)


def timed(fn):
    start = time.perf_counter()
    out = fn()
    return out, (time.perf_counter() - start) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset-root", type=Path, required=True, help="A dataset written by `predvla convert`.")
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=12, help="Paired rounds after one warm-up round.")
    args = parser.parse_args()
    datasets.disable_progress_bars()
    torch.manual_seed(0)
    with tempfile.TemporaryDirectory() as tmp:
        copy_root, copy_s = timed(lambda: features_only_copy(args.dataset_root, Path(tmp) / "copy").root)
        cfg, dataset, full_loader = loader(args.dataset_root.resolve(), args.batch, seed=1)
        _, _, copy_loader = loader(copy_root, args.batch, seed=1)
        policy = make_policy(cfg.policy, ds_meta=dataset.meta)
        preprocessor, _ = make_pre_post_processors(cfg.policy, dataset_stats=dataset.meta.stats)
        optimizer, lr_scheduler = make_optimizer_and_scheduler(cfg, policy)
        accelerator = Accelerator(step_scheduler_with_optimizer=False, cpu=True)
        policy, optimizer = accelerator.prepare(policy, optimizer)
        meters = {name: AverageMeter(name, ":.3f") for name in ("loss", "grad_norm", "lr", "update_s", "dataloading_s")}
        tracker = MetricsTracker(args.batch, dataset.num_frames, dataset.num_episodes, meters, accelerator=accelerator)
        policy.train()
        cameras = set(dataset.meta.camera_keys)
        times = {"load_ms_original": [], "load_ms_copy": [], "update_ms": []}
        full_batches, copy_batches = iter(full_loader), iter(copy_loader)
        for i in range(args.rounds + 1):  # round 0 warms up
            full, load_full = timed(lambda: next(full_batches))
            fast, load_copy = timed(lambda: next(copy_batches))
            assert set(full) - set(fast) == cameras  # the same samples, less the frames
            assert all(torch.equal(full[k], fast[k]) for k in fast if isinstance(fast[k], torch.Tensor))
            _, update = timed(lambda batch=fast: update_policy(
                tracker, policy, preprocessor(batch), optimizer, cfg.optimizer.grad_clip_norm,
                accelerator=accelerator, lr_scheduler=lr_scheduler))
            if i:
                for key, value in zip(times, (load_full, load_copy, update), strict=True):
                    times[key].append(value)
    med = {key: round(statistics.median(values), 1) for key, values in times.items()}
    step_ratio = (med["load_ms_original"] + med["update_ms"]) / (med["load_ms_copy"] + med["update_ms"])
    print(json.dumps({
        **med, "copy_s": round(copy_s / 1e3, 1), "batch": args.batch, "rounds": args.rounds,
        "load_ratio": round(med["load_ms_original"] / med["load_ms_copy"], 1), "step_ratio": round(step_ratio, 2),
    }, indent=1))


if __name__ == "__main__":
    main()
