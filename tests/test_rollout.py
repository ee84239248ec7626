"""PredVLA on a robot through LeRobot: `lerobot-rollout` end to end on the dataset-replay robot, and what holds
the control rate and stops bad runs (camera names, task, error regression's time budget, long episodes).

The robot is `--robot.type=predvla_replay` (lerobot_predvla/robots/): an SO-101-layout episode played as live
observations, registered through LeRobot's robot and camera config registries by the plugin. The policy is trained
for two steps with the real `lerobot-train` (tests/test_lerobot_dataset.py's `prepare`).
"""

import json
import logging
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.policies.factory import make_pre_post_processors
from lerobot.policies.utils import prepare_observation_for_inference
from lerobot.processor import PolicyProcessorPipeline
from lerobot.utils.constants import ACTION, OBS_STATE
from lerobot_factory import SO101
from libero_factory import BIN
from test_lerobot_dataset import prepare
from test_policy import randomised_policy, run, stream

from lerobot_predvla import PredVLAConfig, PredVLAPolicy
from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep
from lerobot_predvla.policies.common.observation_guard import ObservationGuard
from lerobot_predvla.robots.replay import as_camera_frame

SMALL = {"module_dims": (16, 32, 32, 32), "latent_dim": 8, "bottleneck_dim": 8, "head_hidden_dim": 32}  # fast ticks
TASK = "pick up the red cube"  # an SO-101 training task of `prepare("so101")`


def rollout(*args: str) -> subprocess.CompletedProcess:
    """`lerobot-rollout` with one intra-op thread, as `one_thread` gives the replays here: a second thread splits
    the front end's sums differently, and error regression's Adam steps grow that rounding (1e-6 to 1e-3 in 15
    ticks), so the rollout's actions equal a replay's only at the same thread count."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run([str(BIN / "lerobot-rollout"), *args, "--play_sounds=false",
                           "--return_to_initial_position=false"], capture_output=True, text=True, env=env, timeout=300)


@pytest.fixture(autouse=True)
def one_thread():
    """Batch-1 ticks are latency-bound: one intra-op thread (two spin against each other on busy cores)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def so101(tmp_path_factory) -> dict:
    return prepare("so101", tmp_path_factory.mktemp("so101"))


def load(checkpoint: Path) -> tuple[PredVLAPolicy, PolicyProcessorPipeline, PolicyProcessorPipeline]:
    config = PredVLAConfig.from_pretrained(checkpoint)
    policy = PredVLAPolicy.from_pretrained(checkpoint, config=config).eval()
    pre, post = make_pre_post_processors(config, pretrained_path=str(checkpoint))
    return policy, pre, post


def act(policy, pre, post, frame: dict, task: str = TASK) -> torch.Tensor:
    """One tick as lerobot-rollout's sync inference engine runs it: raw frame -> processors -> select_action."""
    with torch.inference_mode():
        observation = prepare_observation_for_inference(dict(frame), torch.device("cpu"), task, "predvla_replay")
        return post(policy.select_action(pre(observation))).squeeze(0)


def recorded_frames(dataset: LeRobotDataset, episode: int) -> list[dict]:
    """The observations a rollout recorded, as the robot delivered them (uint8 (H, W, 3) frames, state)."""
    bounds = dataset.meta.episodes[episode]
    frames = []
    for i in range(int(bounds["dataset_from_index"]), int(bounds["dataset_to_index"])):
        item = dataset[i]
        frame = {key: as_camera_frame(item[key]) for key in SO101.cameras}
        frames.append({**frame, OBS_STATE: item[OBS_STATE].numpy(), ACTION: item[ACTION]})
    return frames


@pytest.mark.slow  # trains with lerobot-train, runs lerobot-rollout
def test_lerobot_rollout_drives_the_replay_robot(so101, tmp_path):
    """`lerobot-rollout --policy.path=... --robot.type=predvla_replay`: two recorded episodes, each from a reset
    policy, every action the one the saved processors and policy give on that raw frame, sent by motor name."""
    record, actions_log = tmp_path / "record", tmp_path / "actions.jsonl"
    result = rollout(
        "--strategy.type=episodic", f"--policy.path={so101['checkpoint']}", "--robot.type=predvla_replay",
        f"--robot.dataset_root={so101['root'] / 'source'}", "--robot.episode=1", f"--robot.action_log={actions_log}",
        "--dataset.repo_id=local/rollout_predvla", f"--dataset.root={record}", f"--dataset.single_task={TASK}",
        "--dataset.num_episodes=2", "--dataset.episode_time_s=1.5", "--dataset.reset_time_s=0",
        "--dataset.video=false", "--dataset.push_to_hub=false", "--fps=10",
    )
    log = result.stdout + result.stderr
    assert result.returncode == 0 and "Rollout finished" in log, log[-3000:]

    dataset = LeRobotDataset("local/rollout_predvla", root=record)
    assert dataset.meta.total_episodes == 2
    assert dataset.meta.features[ACTION]["names"] == list(SO101.action_names)  # the robot's motors, by name
    first = recorded_frames(dataset, 0)
    sent = [json.loads(line)["action"] for line in actions_log.read_text().splitlines()]
    assert first and len(sent) >= len(first)
    for frame, action in zip(first, sent, strict=False):  # the robot got each recorded action under its motor names
        assert list(action) == list(SO101.action_names)
        np.testing.assert_allclose(list(action.values()), frame[ACTION].numpy(), rtol=0, atol=1e-6)

    policy, pre, post = load(so101["checkpoint"])
    for episode in range(2):
        policy.reset()
        pre.reset()
        frames = first if episode == 0 else recorded_frames(dataset, 1)
        assert frames, f"episode {episode} recorded no frame"
        replayed = torch.stack([act(policy, pre, post, {k: v for k, v in f.items() if k != ACTION}) for f in frames])
        assert torch.isfinite(replayed).all()
        torch.testing.assert_close(replayed, torch.stack([f[ACTION] for f in frames]), rtol=1e-4, atol=1e-4)

    # Without a reset between the episodes the second one would have started differently.
    policy.reset()
    pre.reset()
    for frame in first:
        act(policy, pre, post, {k: v for k, v in frame.items() if k != ACTION})
    second = recorded_frames(dataset, 1)[0]
    carried = act(policy, pre, post, {k: v for k, v in second.items() if k != ACTION})
    assert not torch.allclose(carried, second[ACTION], rtol=1e-4, atol=1e-4)


@pytest.mark.slow  # trains with lerobot-train, runs lerobot-rollout
def test_robot_dry_run_runs_as_written(tmp_path):
    """docs/robot.md's first commands, as written, in an empty folder (nothing of the repository's but the plugin):
    `predvla demo robot` makes the recording and checkpoint, `lerobot-rollout` plays two episodes on the replay
    robot; the compiled loops are ready before the first tick, and the action log tells the policy's actions from
    LeRobot's own moves between episodes."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "robot.md").read_text()
    start = page.index("```bash\n") + len("```bash\n")
    script = page[start:page.index("\n```", start)]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}"}
    result = subprocess.run(["bash", "-e", "-c", script], cwd=tmp_path, capture_output=True, text=True, env=env,
                            timeout=900)
    log = result.stdout + result.stderr
    assert result.returncode == 0 and "Rollout finished" in log, log[-3000:]
    assert log.index("PredVLA: C++ recurrence ready") < log.index("Recording episode 0"), log[-3000:]
    dataset = LeRobotDataset("local/rollout_predvla", root=tmp_path / "outputs" / "rollout_predvla")
    entries = [json.loads(line) for line in (tmp_path / "outputs" / "replay_actions.jsonl").read_text().splitlines()]
    assert {e["source"] for e in entries} == {"policy", "lerobot"}  # the return to the start pose between episodes
    assert sum(e["source"] == "policy" for e in entries) == dataset.meta.total_frames
    recorded = torch.stack([dataset[i][ACTION] for i in range(dataset.meta.total_frames)])
    sent = torch.tensor([list(e["action"].values()) for e in entries if e["source"] == "policy"])
    torch.testing.assert_close(sent, recorded, rtol=0, atol=1e-6)


@pytest.mark.slow  # trains with lerobot-train, runs lerobot-rollout
def test_lerobot_rollout_stops_on_a_misnamed_camera(so101):
    cameras = "{top: {type: predvla_replay, key: observation.images.front}, " \
              "wrist: {type: predvla_replay, key: observation.images.wrist}}"
    result = rollout(f"--policy.path={so101['checkpoint']}", "--robot.type=predvla_replay",
                     f"--robot.dataset_root={so101['root'] / 'source'}", f"--robot.cameras={cameras}",
                     f"--task={TASK}", "--duration=20", "--fps=10")
    log = result.stdout + result.stderr
    assert result.returncode != 0, log[-3000:]
    assert ("PredVLA was trained on the cameras ['observation.images.front', 'observation.images.wrist']; the first "
            "observation has ['observation.images.top', 'observation.images.wrist']") in log, log[-3000:]


@pytest.mark.slow  # trains with lerobot-train (the fixture)
def test_replay_robot_serves_the_episode_and_rejects_other_motors(so101, tmp_path):
    from lerobot_predvla.robots import DatasetReplayRobot, DatasetReplayRobotConfig

    root = so101["root"] / "source"
    robot = DatasetReplayRobot(DatasetReplayRobotConfig(dataset_root=str(root), episode=1, calibration_dir=tmp_path))
    assert list(robot.action_features) == list(SO101.action_names)
    robot.connect()
    episode = LeRobotDataset("local/so101", root=root)
    start = int(episode.meta.episodes[1]["dataset_from_index"])
    for t in range(2):
        observation, recorded = robot.get_observation(), episode[start + t]
        assert [observation[name] for name in SO101.state_names] == recorded[OBS_STATE].tolist()
        np.testing.assert_array_equal(observation["front"], as_camera_frame(recorded["observation.images.front"]))
    action = dict.fromkeys(SO101.action_names, 0.5)
    assert robot.send_action(action) == action and robot.actions == [action]
    swapped = {("elbow.pos" if k == "elbow_flex.pos" else k): v for k, v in action.items()}
    with pytest.raises(ValueError, match=r"missing \['elbow_flex.pos'\], unknown \['elbow.pos'\]"):
        robot.send_action(swapped)
    robot.disconnect()
    with pytest.raises(ValueError, match="--robot.episode=7"):
        DatasetReplayRobotConfig(dataset_root=str(root), episode=7)


def raw_frame(step: int = 0) -> dict:
    rng = np.random.default_rng(step)
    frame = {key: rng.integers(0, 256, (*shape, 3), dtype=np.uint8) for key, shape in SO101.cameras.items()}
    return {**frame, OBS_STATE: rng.normal(size=len(SO101.state_names)).astype(np.float32)}


@pytest.mark.slow  # trains with lerobot-train
@pytest.mark.parametrize("task", ["", "   ", None])
def test_an_empty_task_is_an_error_naming_the_flag(so101, task):
    policy, pre, post = load(so101["checkpoint"])
    with pytest.raises(ValueError, match="--task="):
        with torch.inference_mode():
            observation = prepare_observation_for_inference(raw_frame(), torch.device("cpu"), None)
            pre({**observation, "task": task})


@pytest.mark.slow  # trains with lerobot-train
def test_first_observation_needs_every_trained_camera_later_ones_are_masked(so101):
    policy, pre, post = load(so101["checkpoint"])
    frame = raw_frame()
    renamed = {("observation.images.top" if k == "observation.images.front" else k): v for k, v in frame.items()}
    with pytest.raises(KeyError, match=r"trained on the cameras .*'observation.images.top'"):
        act(policy, pre, post, renamed)
    missing = {k: v for k, v in frame.items() if k != "observation.images.front"}
    with pytest.raises(KeyError, match=r"missing \['observation.images.front'\]"):
        act(policy, pre, post, missing)
    policy.reset()
    pre.reset()
    actions = [act(policy, pre, post, frame)] + [act(policy, pre, post, missing) for _ in range(4)]
    assert torch.isfinite(torch.stack(actions)).all()
    assert policy.guard.totals[OBS_VISION_FEATURES] == 1  # the 5th tick refreshes vision: the dropped frame


@pytest.mark.slow  # trains with lerobot-train
def test_front_end_encodes_on_refresh_ticks_only_and_follows_the_device(so101, monkeypatch):
    checkpoint = so101["checkpoint"]
    steps = json.loads((checkpoint / "policy_preprocessor.json").read_text())["steps"]
    names = [s["registry_name"] for s in steps]
    assert names.index("device_processor") < names.index("predvla_frontend_processor")  # encoders after the move
    saved = steps[names.index("predvla_frontend_processor")]["config"]
    assert "device" not in saved and saved["refresh_interval"] == 4  # nothing pins the CPU

    policy, pre, post = load(checkpoint)
    step = next(s for s in pre.steps if isinstance(s, FrontendProcessorStep))
    encoded = []
    encode = step.frontend().encode_images
    monkeypatch.setattr(step.frontend(), "encode_images", lambda images: encoded.append(1) or encode(images))
    frames = [raw_frame(t) for t in range(9)]
    every_fourth = torch.stack([act(policy, pre, post, f) for f in frames])
    assert len(encoded) == 3  # ticks 0, 4 and 8
    assert step.frontend().vision.device == torch.device("cpu")  # where the images arrived (--policy.device)

    # Encoding every tick gives the same actions: error regression reads vision on refresh ticks only (Eq. 9).
    policy.reset()
    pre.reset()
    step.refresh_interval = 1
    every_tick = torch.stack([act(policy, pre, post, f) for f in frames])
    assert len(encoded) == 3 + 9
    torch.testing.assert_close(every_fourth, every_tick, rtol=0, atol=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.slow  # trains with lerobot-train
def test_front_end_runs_on_the_policy_device(so101):
    config = PredVLAConfig.from_pretrained(so101["checkpoint"])
    policy = PredVLAPolicy.from_pretrained(so101["checkpoint"], config=config).to("cuda").eval()
    pre, post = make_pre_post_processors(config, pretrained_path=str(so101["checkpoint"]),
                                         preprocessor_overrides={"device_processor": {"device": "cuda"}})
    with torch.inference_mode():
        observation = prepare_observation_for_inference(raw_frame(), torch.device("cuda"), TASK)
        batch = pre(observation)
        action = post(policy.select_action(batch))
    step = next(s for s in pre.steps if isinstance(s, FrontendProcessorStep))
    assert step.frontend("cuda").vision.device.type == "cuda" and batch[OBS_VISION_FEATURES].is_cuda
    assert torch.isfinite(action).all()


def test_error_regression_deadline_runs_fewer_iterations(caplog):
    observations = stream(6)
    full = randomised_policy(er_iterations=10, **SMALL)
    full_actions = run(full, observations)
    assert (full.error_regression.iterations.fewest, full.error_regression.iterations.most) == (10, 10)

    tight = randomised_policy(er_iterations=10, er_deadline_ms=0.001, **SMALL)
    actions = run(tight, observations)
    counts = tight.error_regression.iterations
    assert torch.isfinite(actions).all() and counts.steps == 6
    assert counts.fewest == counts.most == 1  # at least one iteration, never more than the budget allows
    with caplog.at_level(logging.INFO):
        tight.reset()
    line = "error regression within 0.001 ms ran 1.0 per control step (fewest 1, most 1) of 10 iterations"
    assert line in caplog.text

    roomy = randomised_policy(er_iterations=10, er_deadline_ms=60_000, **SMALL)
    torch.testing.assert_close(run(roomy, observations), full_actions, rtol=0, atol=0)
    with pytest.raises(ValueError, match="er_deadline_ms"):
        PredVLAConfig(er_deadline_ms=0)


def test_episode_three_times_the_training_length_slides_the_window():
    """Past the training sequence length the window keeps sliding (Section 3.5): W steps at most, the carried
    state from the window's start on, actions finite; nothing grows with the episode."""
    policy = randomised_policy(sequence_length=8, er_window=4, er_iterations=2, **SMALL)
    actions = run(policy, stream(3 * 8))
    er = policy.error_regression
    assert actions.shape == (24, 1, 7) and torch.isfinite(actions).all()
    assert er.step_index == 24 and len(er.posteriors) == len(er.vision) == len(er.proprio) == 4


def test_masked_frames_are_logged_while_the_episode_runs(caplog):
    guard = ObservationGuard(("x",), (3,), "mask", "predvla", report_interval_s=0.0)
    with caplog.at_level(logging.WARNING):
        guard({"x": torch.tensor([[float("nan"), 0.0, 0.0]])})
    assert "x unavailable (masked) at 1 env-steps" in caplog.text  # no reset needed


def test_a_saved_front_end_device_no_longer_pins_the_encoders():
    """Checkpoints saved before the front end followed the policy's device recorded `device: "cpu"` in the step's
    config: it still loads, is ignored, and is not written again."""
    step = FrontendProcessorStep(artefact=None, device="cpu")
    assert step.get_config() == {"artefact": None, "refresh_interval": 1}
    with pytest.raises(ValueError, match="refresh_interval"):
        FrontendProcessorStep(refresh_interval=0)
