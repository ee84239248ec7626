"""The real `lerobot-train` CLI finds the plugin, trains PredVLA and resumes exactly from a checkpoint."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from lerobot_predvla import PredVLAPolicy
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE

pytestmark = pytest.mark.slow

LEROBOT_TRAIN = str(Path(sys.executable).with_name("lerobot-train"))


def train(dataset: Path, out: Path, steps: int, *extra: str) -> str:
    cmd = [
        LEROBOT_TRAIN, "--policy.type=predvla", "--dataset.repo_id=local/predvla_synthetic",
        f"--dataset.root={dataset}", "--policy.push_to_hub=false", "--policy.device=cpu", "--num_workers=0",
        f"--steps={steps}", "--save_freq=2", "--log_freq=1", "--batch_size=2", "--wandb.enable=false",
        "--policy.sequence_length=32", f"--output_dir={out}", "--seed=3", *extra,
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result.stdout + result.stderr


def checkpoint(out: Path, step: int) -> Path:
    return out / "checkpoints" / f"{step:06d}" / "pretrained_model"


@pytest.fixture(scope="module")
def four_steps(synthetic_dataset, tmp_path_factory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("train") / "run"
    return out, train(synthetic_dataset, out, 4)


def test_lerobot_train_discovers_and_trains_predvla(four_steps):
    out, log = four_steps
    assert "action_nll" in log and "complexity" in log  # PredVLA's loss terms are logged
    ckpt = checkpoint(out, 4)
    weights = load_file(ckpt / "model.safetensors")
    assert not any("posterior" in k for k in weights)
    assert load_file(ckpt / POSTERIOR_STORE_FILE)["latents"].shape == (8, 32, 256)
    policy = PredVLAPolicy.from_pretrained(ckpt)
    assert sum(p.numel() for p in policy.parameters()) == 675_732


def test_resume_continues_exactly(synthetic_dataset, four_steps, tmp_path):
    full, _ = four_steps
    resumed = tmp_path / "run"
    shutil.copytree(full, resumed, symlinks=True)
    shutil.rmtree(resumed / "checkpoints" / "000004")
    (resumed / "checkpoints" / "last").unlink()
    (resumed / "checkpoints" / "last").symlink_to("000002")
    train(synthetic_dataset, resumed, 4, "--resume=true",
          f"--config_path={checkpoint(resumed, 2) / 'train_config.json'}")
    for name in ("model.safetensors", POSTERIOR_STORE_FILE):
        a, b = load_file(checkpoint(full, 4) / name), load_file(checkpoint(resumed, 4) / name)
        assert a.keys() == b.keys()
        for key in a:
            assert torch.equal(a[key], b[key]), f"{name}:{key} differs after resume"
    # Resuming really continued from step 2: the step-2 and step-4 posteriors differ.
    assert not torch.equal(load_file(checkpoint(full, 2) / POSTERIOR_STORE_FILE)["latents"],
                           load_file(checkpoint(full, 4) / POSTERIOR_STORE_FILE)["latents"])
