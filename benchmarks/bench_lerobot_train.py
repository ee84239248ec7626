"""One `lerobot-train` step of PredVLA, built with LeRobot 0.6.1's own functions, on a dataset made offline.

The step is the body of `lerobot.scripts.lerobot_train.train`'s loop: the next batch of LeRobot's
`DataLoader` over a `LeRobotDataset`, the policy's preprocessor, then `update_policy` (forward, backward,
gradient clip through the Accelerator, optimizer step, `policy.update()`: the posteriors' row-wise Adam).
The dataset is the synthetic one of `predvla synthetic` (the converter's columns: `observation.vision_features`
192, `observation.language_features` 64, `observation.state` 9, `action` 7), written with
`LeRobotDataset.create` / `add_frame` / `save_episode` / `finalize`; every episode is `steps` frames long, so
each training sequence is `steps` valid steps, the fast path's shape.
"""

import time
from collections.abc import Callable
from itertools import cycle
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
from torch import nn

from lerobot_predvla.data.synthetic import make_synthetic_dataset
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy

EPISODES_PER_TASK = 8  # x 2 tasks: 16 episodes of `steps` frames (3,200 frames at 200 steps, ~5 s to write)


def lerobot_train_step_fn(
    root: Path, batch: int, steps: int, weights: nn.Module | None = None, lengths: tuple[int, int] | None = None
) -> tuple[Callable[[], float], PredVLAPolicy]:
    """The loop body of `lerobot-train --policy.type=predvla --batch_size=batch --num_workers=0` on a fresh
    dataset under `root` (which must not exist), training sequences of `steps`. Episodes are `steps` frames long, or
    between `lengths` (min, max) frames. `weights`, a `PredictiveModel`, sets the network's weights.
    Returns the step (it returns the loss) and the policy."""
    datasets.disable_progress_bars()
    shortest, longest = lengths or (steps, steps)
    make_synthetic_dataset(root / "dataset", episodes_per_task=EPISODES_PER_TASK, min_length=shortest,
                           max_length=longest, progress=False)
    policy_config = PredVLAConfig(device="cpu", sequence_length=steps, push_to_hub=False)
    cfg = TrainPipelineConfig(
        dataset=DatasetConfig(repo_id="local/predvla_bench", root=str(root / "dataset")), policy=policy_config,
        output_dir=root / "train", batch_size=batch, num_workers=0, steps=1_000_000,
    )
    cfg.validate()  # the optimizer and scheduler presets of the policy, as lerobot-train takes them
    dataset, _ = make_train_eval_datasets(cfg)
    policy = make_policy(cfg.policy, ds_meta=dataset.meta)
    if weights is not None:
        policy.model.load_state_dict(weights.state_dict())
    preprocessor, _ = make_pre_post_processors(cfg.policy, dataset_stats=dataset.meta.stats)
    optimizer, lr_scheduler = make_optimizer_and_scheduler(cfg, policy)
    accelerator = Accelerator(step_scheduler_with_optimizer=False, cpu=True)
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch, shuffle=True, num_workers=0, drop_last=False)
    policy, optimizer, loader, lr_scheduler = accelerator.prepare(policy, optimizer, loader, lr_scheduler)
    meters = {name: AverageMeter(name, ":.3f") for name in ("loss", "grad_norm", "lr", "update_s", "dataloading_s")}
    tracker = MetricsTracker(batch, dataset.num_frames, dataset.num_episodes, meters, accelerator=accelerator)
    batches = cycle(loader)
    policy.train()

    def step() -> float:
        start = time.perf_counter()
        batch = preprocessor(next(batches))
        tracker.dataloading_s = time.perf_counter() - start
        update_policy(tracker, policy, batch, optimizer, cfg.optimizer.grad_clip_norm, accelerator=accelerator,
                      lr_scheduler=lr_scheduler)
        tracker.step()
        return tracker.loss.val

    return step, policy
