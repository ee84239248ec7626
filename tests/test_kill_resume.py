"""Training that survives being killed: SHA-256 manifests, atomic checkpoints, the output-folder lock and the
fault-injection harness killing a real `lerobot-train` (docs/reliability.md, "Killed trainings")."""

import dataclasses
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from lerobot.utils.constants import CHECKPOINTS_DIR, LAST_CHECKPOINT_LINK, PRETRAINED_MODEL_DIR, TRAINING_STATE_DIR

from lerobot_predvla.hub.upload import push_checkpoint
from lerobot_predvla.sweep.kill_resume import (
    HarnessConfig,
    checkpoint_dir,
    load_through_lerobot,
    run_harness,
    train_command,
)
from lerobot_predvla.utils.checkpoints import (
    kill_point,
    remove_leftovers,
    save_checkpoint_atomically,
    update_last_checkpoint_atomically,
)
from lerobot_predvla.utils.manifest import MANIFEST_FILE, read_manifest, verify_manifests, write_manifest
from lerobot_predvla.utils.run_lock import LOCK_FILE
from lerobot_predvla.utils.safe_loading import CheckpointError


# ----- manifests and atomic publication (in process) -----------------------------------------------------------
def folder(tmp_path: Path) -> Path:
    directory = tmp_path / "pretrained_model"
    (directory / "sub").mkdir(parents=True)
    (directory / "model.safetensors").write_bytes(bytes(range(256)) * 8)
    (directory / "config.json").write_text('{"type": "predvla"}')
    (directory / "sub" / "extra.json").write_text("{}")
    (directory / ".model.safetensors.123.tmp").write_text("half")  # temporary files are not listed
    write_manifest(directory)
    return directory


def test_manifest_lists_every_file_and_verifies(tmp_path):
    directory = folder(tmp_path)
    assert sorted(read_manifest(directory)) == ["config.json", "model.safetensors", "sub/extra.json"]
    assert verify_manifests(directory)


@pytest.mark.parametrize(("spoil", "words"), [
    (lambda p: p.write_bytes(p.read_bytes()[:-1]), "truncated: 2047 bytes, the manifest records 2048"),
    (lambda p: p.write_bytes(p.read_bytes() + b"\0"), "grown"),
    (lambda p: p.write_bytes(p.read_bytes()[:100] + bytes([p.read_bytes()[100] ^ 1]) + p.read_bytes()[101:]),
     "altered"),
    (lambda p: p.unlink(), "missing"),
])
def test_a_spoiled_file_is_named(tmp_path, spoil, words):
    directory = folder(tmp_path)
    spoil(directory / "model.safetensors")
    with pytest.raises(CheckpointError, match=words) as err:
        verify_manifests(directory)
    assert str(directory / "model.safetensors") in str(err.value)


def test_a_folder_without_manifest_loads_with_one_log_line(tmp_path, caplog):
    directory = folder(tmp_path)
    (directory / MANIFEST_FILE).unlink()
    other = folder(tmp_path / "other")
    (other / MANIFEST_FILE).unlink()
    with caplog.at_level(logging.INFO):
        assert not verify_manifests(directory, other)
    assert [r.getMessage() for r in caplog.records if MANIFEST_FILE in r.getMessage()] == [
        f"No {MANIFEST_FILE} in {directory}, {other} (a checkpoint saved without one, or another tool's): "
        "files not verified."
    ]


def test_a_corrupt_manifest_is_named(tmp_path):
    directory = folder(tmp_path)
    (directory / MANIFEST_FILE).write_text('{"files": ')
    with pytest.raises(CheckpointError, match="not a readable manifest"):
        verify_manifests(directory)


def fake_lerobot_save(checkpoint: Path, step: int, fail: bool = False) -> None:
    """Writes a checkpoint's two folders as LeRobot's save_checkpoint does; `fail` stops it midway."""
    (checkpoint / PRETRAINED_MODEL_DIR).mkdir(parents=True)
    (checkpoint / PRETRAINED_MODEL_DIR / "model.safetensors").write_bytes(b"w" * step)
    if fail:
        raise KeyboardInterrupt
    (checkpoint / TRAINING_STATE_DIR).mkdir()
    (checkpoint / TRAINING_STATE_DIR / "training_step.json").write_text(json.dumps({"step": step}))


def test_a_checkpoint_appears_whole_or_not_at_all(tmp_path):
    checkpoints = tmp_path / CHECKPOINTS_DIR
    checkpoints.mkdir()
    for step in (2, 4):
        save_checkpoint_atomically(fake_lerobot_save, checkpoints / f"{step:06d}", step)
        update_last_checkpoint_atomically(checkpoints / f"{step:06d}")
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint_atomically(fake_lerobot_save, checkpoints / "000006", 6, fail=True)
    assert sorted(p.name for p in checkpoints.iterdir()) == [".000006.partial", "000002", "000004", "last"]
    assert os.readlink(checkpoints / LAST_CHECKPOINT_LINK) == "000004"
    assert verify_manifests(checkpoints / "000004" / PRETRAINED_MODEL_DIR, checkpoints / "000004" / TRAINING_STATE_DIR)
    # An attempt killed after publishing 000004 but before moving `last` leaves it; the next write replaces it.
    save_checkpoint_atomically(fake_lerobot_save, checkpoints / "000004", 5)
    assert (checkpoints / "000004" / PRETRAINED_MODEL_DIR / "model.safetensors").read_bytes() == b"w" * 5
    assert [p.name for p in remove_leftovers(checkpoints)] == [".000006.partial"]
    assert sorted(p.name for p in checkpoints.iterdir()) == ["000002", "000004", "last"]


def test_the_kill_hook_checks_its_setting(tmp_path, monkeypatch):
    monkeypatch.setenv("PREDVLA_KILL_AT", "weights-saved@4")
    kill_point("weights-saved", tmp_path / CHECKPOINTS_DIR / ".000002.partial" / PRETRAINED_MODEL_DIR)  # another step
    kill_point("staged", tmp_path / CHECKPOINTS_DIR / ".000004.partial")  # another point
    monkeypatch.setenv("PREDVLA_KILL_AT", "halfway@4")
    with pytest.raises(ValueError, match="PREDVLA_KILL_AT='halfway@4': expected <point>@<step>"):
        kill_point("staged", tmp_path)


# ----- the real lerobot-train, killed -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def harness(synthetic_dataset, tmp_path_factory) -> tuple[HarnessConfig, dict]:
    """Two kills of a real lerobot-train (8 steps, a checkpoint every 2): one at a random step after the first
    checkpoint, as soon as that step is logged (a later moment can fall after so short a run has ended), one forced
    inside the write of the weights of a checkpoint; resumed to the end."""
    cfg = HarnessConfig(output_dir=tmp_path_factory.mktemp("killed") / "run", dataset_root=synthetic_dataset,
                        steps=8, save_freq=2, kills=2, forced_every=2, min_kill_step=3, max_delay_s=0.0,
                        reference=False)
    return cfg, run_harness(cfg)


@pytest.mark.slow
def test_killed_inside_a_checkpoint_write_resumes_from_the_previous_checkpoint(harness):
    cfg, report = harness
    assert report["failures"] == 0, report["problems"]
    assert report["kills"] == 2 and report["resumes"] >= 2
    forced = report["kill_log"][1]
    step = int(forced["kind"].rsplit("@", 1)[1])
    assert forced["kind"].startswith("forced:weights-saved@") and step % cfg.save_freq == 0
    # Killed while writing checkpoint `step`: `last` stayed on the previous one, the next attempt resumed there.
    assert forced["last_after"] == forced["resumed_from"] == step - cfg.save_freq
    assert report["steps_lost_per_kill"]["max"] <= cfg.save_freq
    checkpoints = Path(cfg.output_dir) / CHECKPOINTS_DIR
    assert os.readlink(checkpoints / LAST_CHECKPOINT_LINK) == f"{cfg.steps:06d}"
    assert not [p.name for p in checkpoints.glob(".*")]  # the staging folder was cleared on resume


@pytest.mark.slow
@pytest.mark.parametrize("name", [
    "pretrained_model/model.safetensors", "pretrained_model/posterior_store.safetensors",
    "pretrained_model/config.json", "pretrained_model/train_config.json", "pretrained_model/policy_preprocessor.json",
    "pretrained_model/policy_preprocessor_step_4_normalizer_processor.safetensors",
    "pretrained_model/policy_postprocessor.json",
    "training_state/optimizer_state.safetensors", "training_state/optimizer_param_groups.json",
    "training_state/rng_state.safetensors", "training_state/training_step.json",
])
def test_one_altered_byte_of_any_checkpoint_file_is_named(harness, tmp_path, name):
    cfg, _ = harness
    ckpt = tmp_path / CHECKPOINTS_DIR / "000008"
    shutil.copytree(checkpoint_dir(Path(cfg.output_dir), cfg.steps), ckpt)
    data = bytearray((ckpt / name).read_bytes())
    if name.endswith(".json"):  # still valid JSON of the same content: an indentation space becomes a tab
        data[data.rindex(b"\n ") + 1] = ord("\t")
        json.loads(data)
    else:
        data[len(data) // 2] ^= 0x01
    (ckpt / name).write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="altered") as err:
        load_through_lerobot(cfg, ckpt)
    assert str(ckpt / name) in str(err.value)


@pytest.mark.slow
def test_a_second_training_on_a_held_output_folder_refuses_naming_the_holder(harness, tmp_path):
    cfg, _ = harness
    out = tmp_path / "run"
    shutil.copytree(cfg.output_dir, out, symlinks=True)
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from lerobot_predvla.utils.run_lock import lock_output_dir; "
         "lock_output_dir(sys.argv[1]); print('held', flush=True); time.sleep(600)", str(out)],
        stdout=subprocess.PIPE, text=True, start_new_session=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        cmd = train_command(dataclasses.replace(cfg, steps=cfg.steps + 2), out, resume=True)
        result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"},
                                timeout=500)
        assert result.returncode != 0
        assert f"{out.resolve()}: another training holds this output folder (pid {holder.pid}" in result.stderr
    finally:
        os.killpg(holder.pid, signal.SIGKILL)
        holder.wait()
    time.sleep(0.1)
    assert json.loads((out / LOCK_FILE).read_text())["pid"] == holder.pid  # a stale record; the lock is gone
    probe = subprocess.run([sys.executable, "-c", "import sys; from lerobot_predvla.utils.run_lock import "
                            "lock_output_dir; lock_output_dir(sys.argv[1])", str(out)], timeout=500)
    assert probe.returncode == 0


@pytest.mark.slow
def test_a_pushed_checkpoint_carries_the_manifest_of_its_files(harness, tmp_path):
    cfg, _ = harness
    published, _ = push_checkpoint(checkpoint_dir(Path(cfg.output_dir), cfg.steps), "me/predvla", dry_run=True)
    assert set(json.loads(published[MANIFEST_FILE])["files"]) == set(published) - {MANIFEST_FILE}
    for rel, src in published.items():  # the repository as a user downloads it verifies
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(src if isinstance(src, bytes) else Path(src).read_bytes())
    assert verify_manifests(tmp_path)
    (tmp_path / "README.md").write_text("edited")
    with pytest.raises(CheckpointError, match="README.md: truncated"):
        verify_manifests(tmp_path)
