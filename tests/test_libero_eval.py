"""Real `lerobot-eval` of a tiny PredVLA checkpoint on LIBERO (`--env.type=predvla_libero` and LeRobot's `libero`).

The checkpoint is trained for two steps on a converted dataset whose front end was fitted offline
(`--vision-weights random`); the evaluation runs the simulator for one truncated episode.
"""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from libero_factory import BIN, run, write_libero_file
from test_conversion import SUITE, convert, run_cli

from lerobot_predvla.columns import OBS_IMAGE_FRESH, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.frontend import FrontendArtefact, FrozenFrontend
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep

pytestmark = pytest.mark.simulator

SOUP = "pick up the alphabet soup and place it in the basket"  # libero_object task 0
EPISODE_STEPS = 9


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eval")
    write_libero_file(root / "hdf5" / SUITE / "soup_demo.hdf5", SOUP, [12, 10], seed=4)
    frontend = root / "frontend"
    assert run_cli(["fit-frontend", "--hdf5-root", str(root / "hdf5"), "--suites", SUITE,
                    "--vision-weights", "random", "--out", str(frontend)]) == 0
    dataset = root / "dataset"
    assert convert(root / "hdf5", frontend, dataset, "--image-storage", "png", "--repo-id", "local/soup") == 0
    run([str(BIN / "lerobot-train"), "--policy.type=predvla", "--dataset.repo_id=local/soup",
         f"--dataset.root={dataset}", "--policy.push_to_hub=false", "--policy.device=cpu", "--num_workers=0",
         "--steps=2", "--save_freq=2", "--batch_size=2", "--wandb.enable=false", "--policy.sequence_length=16",
         "--policy.er_window=4", "--policy.er_iterations=2", f"--output_dir={root / 'train'}"])
    return root / "train" / "checkpoints" / "000002" / "pretrained_model"


def test_checkpoint_carries_the_front_end(checkpoint):
    config = json.loads((checkpoint / "policy_preprocessor.json").read_text())
    step = next(s for s in config["steps"] if s["registry_name"] == "predvla_frontend_processor")
    dataset_copy = FrontendArtefact.load(Path(json.loads((checkpoint / "config.json").read_text())["frontend_dir"]))
    assert step["config"]["artefact"] == json.loads(json.dumps(dataset_copy.metadata()))
    assert step["state_file"] and (checkpoint / step["state_file"]).is_file()


def test_front_end_step_encodes_fresh_images_only(checkpoint):
    from lerobot.processor import PolicyProcessorPipeline

    pipeline = PolicyProcessorPipeline.from_pretrained(checkpoint, config_filename="policy_preprocessor.json")
    step = next(s for s in pipeline.steps if isinstance(s, FrontendProcessorStep))
    frontend = FrozenFrontend(step.frontend().artefact, verbose=False)
    rng = np.random.default_rng(0)
    images = [{k: torch.from_numpy(rng.random((1, 3, 128, 128), dtype=np.float32)) for k in frontend.artefact.cameras}
              for _ in range(2)]
    out = []
    for image, fresh in zip(images, (1.0, 0.0), strict=True):
        batch = {**image, "observation.state": torch.zeros(1, 9), OBS_IMAGE_FRESH: torch.tensor([[fresh]]),
                 "task": [SOUP]}
        out.append(pipeline(batch))
    expected = frontend.encode_images(images[0])
    torch.testing.assert_close(out[0][OBS_VISION_FEATURES], expected, rtol=0, atol=0)
    torch.testing.assert_close(out[1][OBS_VISION_FEATURES], expected, rtol=0, atol=0)  # not refreshed
    torch.testing.assert_close(out[0][OBS_LANGUAGE_FEATURES], frontend.encode_instructions([SOUP]), rtol=0, atol=0)


@pytest.mark.parametrize("env_type", ["predvla_libero", "libero"])
def test_lerobot_eval_runs_predvla_on_libero(checkpoint, tmp_path, env_type):
    log = run([str(BIN / "lerobot-eval"), f"--policy.path={checkpoint}", f"--env.type={env_type}",
               f"--env.task={SUITE}", "--env.task_ids=[0]", f"--env.episode_length={EPISODE_STEPS}",
               "--eval.n_episodes=1", "--eval.batch_size=1", "--eval.use_async_envs=false", "--policy.device=cpu",
               f"--output_dir={tmp_path}"])
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1, log[-2000:]
    assert 0.0 <= info["overall"]["pc_success"] <= 100.0


def test_predvla_trace_records_error_regression_in_the_simulator(checkpoint, tmp_path):
    """`predvla trace`: lerobot-eval run for real, every control step traced, a figure beside an earlier trace."""
    eval_args = [f"--policy.path={checkpoint}", "--env.type=predvla_libero", f"--env.task={SUITE}",
                 "--env.task_ids=[0]", f"--env.episode_length={EPISODE_STEPS}", "--eval.n_episodes=2",
                 "--eval.batch_size=2", "--eval.use_async_envs=false", "--policy.device=cpu"]
    predvla = str(BIN / "predvla")
    run([predvla, "trace", str(tmp_path / "er"), *eval_args])
    trace = json.loads((tmp_path / "er" / "trace.json").read_text())
    assert len(trace["episodes"]) == 2 and (tmp_path / "er" / "eval" / "eval_info.json").is_file()
    assert trace["omp_num_threads"] == os.environ.get("OMP_NUM_THREADS")
    for episode in trace["episodes"]:
        assert episode["steps"] == list(range(1, EPISODE_STEPS + 1))
        assert np.isfinite(episode["action"]).all() and np.shape(episode["action"]) == (EPISODE_STEPS, 7)
        moves = np.array(episode["move_newest"])
        assert moves.shape == (EPISODE_STEPS, 4) and np.isfinite(moves).all() and (moves > 0).any()
        assert np.shape(episode["error_before"]) == (EPISODE_STEPS, 2) and np.isfinite(episode["error_before"]).all()
    assert set(trace["correlations"]) == {"vision", "proprio", "median_after_over_before"}
    assert (tmp_path / "er" / "corrections.png").stat().st_size > 0

    log = run([predvla, "trace", "--episode", "1", "--compare", str(tmp_path / "er"), str(tmp_path / "open_loop"),
               *eval_args, "--policy.er_iterations=0"])
    open_loop = json.loads((tmp_path / "open_loop" / "trace.json").read_text())["episodes"][1]
    assert "move_newest" not in open_loop and open_loop["action"] == open_loop["prior_action"]
    assert (tmp_path / "open_loop" / "trace.png").stat().st_size > 0, log[-2000:]

    bad = subprocess.run([predvla, "trace", "--compare", str(tmp_path), str(tmp_path / "x"), *eval_args],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and f"--compare {tmp_path}" in bad.stderr and not (tmp_path / "x").exists()


def test_rendering_only_at_reset_changes_no_action_that_ignores_vision(checkpoint, tmp_path):
    """Exact open loop and A4 (`er_lambda_v=0`) read no camera frame after reset, so their sweeps evaluate with
    `--env.render_interval=100000`: the same actions, bit for bit. Error regression with vision is the control."""
    eval_args = [f"--policy.path={checkpoint}", "--env.type=predvla_libero", f"--env.task={SUITE}",
                 "--env.task_ids=[0]", f"--env.episode_length={EPISODE_STEPS}", "--eval.n_episodes=1",
                 "--eval.batch_size=1", "--eval.use_async_envs=false", "--policy.device=cpu"]

    def actions(name: str, *extra: str) -> list:
        run([str(BIN / "predvla"), "trace", str(tmp_path / name), *eval_args, *extra])
        return json.loads((tmp_path / name / "trace.json").read_text())["episodes"][0]["action"]

    sparse = "--env.render_interval=100000"
    for variant in ("--policy.er_lambda_v=0.0", "--policy.er_iterations=0"):
        assert actions(f"{variant}_rendered", variant) == actions(f"{variant}_sparse", variant, sparse), variant
    rendered, held = actions("er_rendered"), actions("er_sparse", sparse)
    assert rendered[:4] == held[:4] and rendered[4:] != held[4:]  # the first refresh after reset is step 4


def test_predvla_libero_env_observations():
    """Fresh images every 4th step equal the demonstrations' render of the same state; proprio is joints+gripper."""
    from lerobot.envs.utils import preprocess_observation

    from lerobot_predvla.sims.libero import env as libero_env
    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    cfg = PredVLALiberoEnv(task=SUITE, task_ids=[0])
    venv = cfg.create_envs(n_envs=1)[SUITE][0]
    env_pre, _post = cfg.get_env_processors()
    obs, _info = venv.reset(seed=[0])
    inner = venv.envs[0].unwrapped._env
    # The demonstrations' camera env (`predvla demos` renders kept episodes in it by replaying states).
    demo_env = libero_env.make_env(libero_env.task_spec(SUITE, 0), render=True)
    libero_env.random_reset(demo_env, 0)
    libero_env.set_fixture_poses(demo_env, libero_env.fixture_poses(inner))
    fresh_flags = []
    for step in range(6):
        raw = {"image": obs["pixels"]["image"][0], "joints": obs["robot_state"]["joints"]["pos"][0]}
        processed = env_pre(preprocess_observation(obs))
        fresh_flags.append(int(processed[OBS_IMAGE_FRESH].item()))
        joints = torch.from_numpy(obs["robot_state"]["joints"]["pos"]).float()
        gripper = torch.from_numpy(obs["robot_state"]["gripper"]["qpos"]).float()
        torch.testing.assert_close(processed["observation.state"], torch.cat([joints, gripper], -1))
        if step % 4 == 0:
            demo_render = demo_env.regenerate_obs_from_state(inner.get_sim_state())
            assert np.array_equal(raw["image"], demo_render["agentview_image"])
            np.testing.assert_array_equal(raw["joints"], demo_render["robot0_joint_pos"])
            # LeRobot orientation: rotated by 180 degrees, as LiberoProcessorStep does.
            lerobot_image = torch.from_numpy(raw["image"][::-1, ::-1].copy()).permute(2, 0, 1).float() / 255
            torch.testing.assert_close(processed["observation.images.image"][0], lerobot_image)
        obs, *_ = venv.step(np.full((1, 7), 0.2, dtype=np.float32))
    venv.close()
    demo_env.close()
    assert fresh_flags == [1, 0, 0, 0, 1, 0]


def test_a_finished_sub_environment_is_frozen_until_the_next_rollout():
    """Once a sub-environment's episode ends (here a non-finite action faults it), its steps and Gymnasium's autoreset
    replay its last observation with `image_fresh` 0 and simulate nothing while the other goes on; the next rollout's
    reset (LeRobot's NEW_ROLLOUT_OPTION) starts it again."""
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION

    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    venv = PredVLALiberoEnv(task=SUITE, task_ids=[0]).create_envs(n_envs=2)[SUITE][0]
    venv.reset(seed=[0, 1], options={NEW_ROLLOUT_OPTION: True})
    finished, going = (env.unwrapped for env in venv.envs)
    action = np.zeros((2, 7), dtype=np.float32)
    fault = action.copy()
    fault[0] = np.nan
    _obs, _reward, terminated, _truncated, _info = venv.step(fault)
    assert terminated.tolist() == [True, False]
    fresh = []
    for _ in range(6):  # the first of these is Gymnasium's autoreset of sub-environment 0
        obs, _reward, _terminated, _truncated, _info = venv.step(action)
        fresh.append(obs["image_fresh"][:, 0].tolist())
    assert [row[0] for row in fresh] == [0] * 6 and [row[1] for row in fresh] == [0, 0, 1, 0, 0, 0]
    assert (finished._steps_since_reset, finished._rollouts, going._steps_since_reset) == (1, 1, 7)
    venv.reset(seed=[2, 3], options={NEW_ROLLOUT_OPTION: True})
    assert (finished._rollouts, finished._steps_since_reset, finished.nonfinite_actions) == (2, 0, 1)
    venv.step(action)
    assert finished._steps_since_reset == 1
    venv.close()


def test_lerobots_libero_env_gives_predvla_joint_proprio():
    """With `--env.type=libero`, PredVLA policies get joints + gripper; other policies keep LeRobot's 8-dim state."""
    from lerobot.envs import make_env, make_env_pre_post_processors
    from lerobot.envs.configs import LiberoEnv
    from lerobot.envs.utils import preprocess_observation
    from lerobot.policies.act.configuration_act import ACTConfig

    from lerobot_predvla import PredVLAConfig
    from lerobot_predvla.policies.bc_rnn.configuration_predvla_bc_rnn import PredVLABCRNNConfig
    from lerobot_predvla.sims.libero.env import use_headless_gl

    use_headless_gl()  # before LeRobot's LIBERO env loads the simulator
    cfg = LiberoEnv(task=SUITE, task_ids=[0], observation_height=128, observation_width=128)
    venv = make_env(cfg, n_envs=1)[SUITE][0]
    obs, _info = venv.reset(seed=[0])
    venv.close()
    joints = torch.from_numpy(obs["robot_state"]["joints"]["pos"]).float()
    gripper = torch.from_numpy(obs["robot_state"]["gripper"]["qpos"]).float()
    for policy_cfg in (PredVLAConfig(), PredVLABCRNNConfig()):
        env_pre, _post = make_env_pre_post_processors(cfg, policy_cfg)
        processed = env_pre(preprocess_observation(obs))
        torch.testing.assert_close(processed["observation.state"], torch.cat([joints, gripper], -1))
    env_pre, _post = make_env_pre_post_processors(cfg, ACTConfig())
    assert env_pre(preprocess_observation(obs))["observation.state"].shape == (1, 8)  # LeRobot's eef state


def test_published_files_reproduce_actions_front_end_included(checkpoint, tmp_path):
    """A snapshot of exactly the files `predvla push` publishes acts like the checkpoint on raw observations."""
    import shutil

    from lerobot.policies.factory import make_pre_post_processors

    from lerobot_predvla import PredVLAConfig, PredVLAPolicy
    from lerobot_predvla.hub.upload import collect_checkpoint

    files, _ = collect_checkpoint(checkpoint)
    assert any("predvla_frontend_processor" in name and name.endswith(".safetensors") for name in files)
    snapshot = tmp_path / "snapshot"
    for name, path in files.items():
        (snapshot / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, snapshot / name)
    rng = np.random.default_rng(1)
    observations = [
        {"observation.images.image": torch.from_numpy(rng.random((1, 3, 128, 128), dtype=np.float32)),
         "observation.images.image2": torch.from_numpy(rng.random((1, 3, 128, 128), dtype=np.float32)),
         "observation.state": torch.from_numpy(rng.normal(size=(1, 9)).astype(np.float32)),
         OBS_IMAGE_FRESH: torch.tensor([[float(t % 4 == 0)]]), "task": [SOUP]}
        for t in range(5)
    ]
    actions = []
    for source in (checkpoint, snapshot):
        config = PredVLAConfig.from_pretrained(source)
        policy = PredVLAPolicy.from_pretrained(source, config=config)
        pre, post = make_pre_post_processors(config, pretrained_path=str(source))
        with torch.inference_mode():
            actions.append(torch.cat([post(policy.select_action(pre(dict(o)))) for o in observations]))
    torch.testing.assert_close(actions[0], actions[1], rtol=0, atol=0)


def test_step_caps_are_lerobots():
    """The per-suite caps `predvla demos` and the docs use are the ones lerobot-eval applies."""
    from lerobot.envs.libero import TASK_SUITE_MAX_STEPS

    from lerobot_predvla.columns import SUITES
    from lerobot_predvla.sims.libero.protocol import STEP_CAPS

    assert set(STEP_CAPS) == set(SUITES)
    assert {suite: TASK_SUITE_MAX_STEPS[suite] for suite in SUITES} == STEP_CAPS


def test_suites_are_built_quietly(capsys):
    """LIBERO prints "[info] using task orders" whenever it builds a suite; the project's lookups build them silently,
    and an unknown suite's error names the ones that exist."""
    from lerobot_predvla.sims.libero import env as libero_env

    assert libero_env.num_tasks("libero_object") == 10
    assert len(libero_env.libero_instructions()) == 40
    assert libero_env.official_init_states("libero_goal", 0).shape[0] == 50
    assert "using task orders" not in capsys.readouterr().out
    with pytest.raises(ValueError, match="libero_object"):
        libero_env.libero_suite("libero_objects")


def test_a_suite_without_tasks_is_refused_naming_it(monkeypatch):
    from types import SimpleNamespace

    from lerobot_predvla.sims.libero import env as libero_env

    empty = SimpleNamespace(get_benchmark_dict=lambda: {"libero_empty": lambda: SimpleNamespace(tasks=[])})
    monkeypatch.setattr(libero_env, "_libero", lambda: (None, empty))
    with pytest.raises(ValueError, match="'libero_empty' has no tasks"):
        libero_env.libero_suite("libero_empty")
