"""`predvla features-only`: a converted dataset without camera frames gives the same samples and the same training."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot_factory import LIBERO_COMMUNITY, make_dataset
from safetensors.torch import load_file
from test_lerobot_dataset import MILK, SOUP, convert, fit

from lerobot_predvla.cli.main import main as predvla
from lerobot_predvla.columns import FRONTEND_META_DIR


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    """A LIBERO-layout dataset with video cameras, converted by `predvla convert`."""
    root = tmp_path_factory.mktemp("features_only")
    make_dataset(root / "source", LIBERO_COMMUNITY, [(SOUP, 7), (MILK, 6), (SOUP, 5)], use_videos=True)
    assert fit(root / "source", root / "frontend") == 0
    assert convert(root / "source", root / "frontend", root / "converted", "--repo-id", "local/converted") == 0
    return root / "converted"


def test_copy_keeps_every_sample_but_the_camera_frames(converted, tmp_path):
    assert predvla(["features-only", "--dataset-root", str(converted), "--out", str(tmp_path / "copy")]) == 0
    original = LeRobotDataset("local/converted", root=converted)
    copy = LeRobotDataset("local/copy", root=tmp_path / "copy")
    cameras = set(original.meta.camera_keys)
    assert cameras and not copy.meta.camera_keys and not (tmp_path / "copy" / "videos").exists()
    assert set(copy.meta.features) == set(original.meta.features) - cameras
    assert len(copy) == len(original) == 18
    for i in range(len(original)):
        a, b = original[i], copy[i]
        assert set(a) - set(b) == cameras
        for key, value in b.items():
            assert torch.equal(a[key], value) if isinstance(value, torch.Tensor) else a[key] == value, (i, key)
    artefact = sorted(p.relative_to(converted) for p in (converted / FRONTEND_META_DIR).rglob("*") if p.is_file())
    assert artefact
    for path in artefact:
        assert (tmp_path / "copy" / path).read_bytes() == (converted / path).read_bytes()


def test_bad_input_names_the_problem_and_writes_nothing(converted, tmp_path, capsys):
    (tmp_path / "taken").mkdir()
    assert predvla(["features-only", "--dataset-root", str(converted), "--out", str(tmp_path / "taken")]) == 2
    assert "taken already exists" in capsys.readouterr().err
    assert predvla(["features-only", "--dataset-root", str(tmp_path / "nowhere"), "--out", str(tmp_path / "a")]) == 2
    assert "nowhere/meta/info.json not found" in capsys.readouterr().err
    # A dataset without the cached columns still needs its frames to train.
    assert predvla(["features-only", "--dataset-root", str(converted.parent / "source"),
                    "--out", str(tmp_path / "b")]) == 2
    assert "no 'observation.vision_features' column" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def train(root: Path, out: Path, *extra: str) -> Path:
    """The real lerobot-train, BC-Transformer (B1), 4 steps from seed 5; returns the step-4 checkpoint."""
    result = subprocess.run(
        [str(Path(sys.executable).with_name("lerobot-train")), "--policy.type=predvla_bc_transformer",
         "--dataset.repo_id=local/converted", f"--dataset.root={root}", "--policy.push_to_hub=false",
         "--policy.device=cpu", "--num_workers=0", "--steps=4", "--save_freq=2", "--batch_size=4",
         "--wandb.enable=false", "--seed=5", f"--output_dir={out}", *extra],
        capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"},
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out / "checkpoints" / "000004" / "pretrained_model"


def resume_at_step_2(run: Path, out: Path, root: Path) -> Path:
    """A copy of `run` rewound to its step-2 checkpoint, resumed to step 4 with `--dataset.root=root`."""
    shutil.copytree(run, out, symlinks=True)
    shutil.rmtree(out / "checkpoints" / "000004")
    (out / "checkpoints" / "last").unlink()
    (out / "checkpoints" / "last").symlink_to("000002")
    config = out / "checkpoints" / "000002" / "pretrained_model" / "train_config.json"
    return train(root, out, f"--config_path={config}", "--resume=true")


@pytest.mark.slow
def test_training_on_the_copy_makes_the_same_updates(converted, tmp_path):
    """From the start, and resumed onto the copy from a checkpoint of a run on the original (`predvla sweep` does
    this when a sweep gains a `train_root`): the same weights as on the original. (A BC-Transformer resumed is not
    bit-identical to the run it resumes, so resumed runs are compared with each other.)"""
    copy = tmp_path / "copy"
    assert predvla(["features-only", "--dataset-root", str(converted), "--out", str(copy)]) == 0
    runs = {"original": train(converted, tmp_path / "original"), "fresh": train(copy, tmp_path / "fresh")}
    runs["resumed_original"] = resume_at_step_2(tmp_path / "original", tmp_path / "resumed_original", converted)
    runs["resumed_copy"] = resume_at_step_2(tmp_path / "original", tmp_path / "resumed_copy", copy)
    assert json.loads((runs["resumed_copy"] / "train_config.json").read_text())["dataset"]["root"] == str(copy)
    weights = {name: load_file(path / "model.safetensors") for name, path in runs.items()}
    assert len({tuple(w) for w in weights.values()}) == 1
    for a, b in (("original", "fresh"), ("resumed_original", "resumed_copy")):
        for key, value in weights[a].items():
            assert torch.equal(value, weights[b][key]), (a, b, key)
