"""The oracle front end (a diagnostic): simulator object poses relative to the gripper as the visual features.

The unit tests need no simulator; the others run LIBERO for real (libero_object task 0, a few steps, and one
scripted-expert episode, physics only).
"""

import json
import subprocess

import h5py
import numpy as np
import pytest
import torch
from lerobot.configs.types import PipelineFeatureType
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.lerobot_types import TransitionKey
from lerobot.utils.constants import OBS_ENV_STATE
from libero_factory import BIN, run, run_cli, write_libero_file
from scipy.spatial.transform import Rotation

from lerobot_predvla.columns import FRONTEND_META_DIR, OBS_VISION_FEATURES
from lerobot_predvla.frontend import FrontendArtefact, FrontendArtefactError
from lerobot_predvla.frontend.oracle import POSE_DIM, OracleStandardisation
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep

SUITE = "libero_object"
SOUP = "pick up the alphabet soup and place it in the basket"
OBJECTS = {SOUP: ["alphabet_soup_1", "basket_1"]}



@pytest.fixture(scope="module")
def frontend_dir(tmp_path_factory):
    """A front end fitted on tiny generated demonstrations (random ResNet18 weights, offline)."""
    root = tmp_path_factory.mktemp("libero")
    write_libero_file(root / SUITE / "a_demo.hdf5", SOUP, [5, 4], seed=1)
    out = tmp_path_factory.mktemp("fe") / "frontend"
    argv = ["fit-frontend", "--hdf5-root", str(root), "--suites", SUITE, "--vision-weights", "random",
            "--out", str(out)]
    assert run_cli(argv) == 0
    return out


def test_standardisation_fits_applies_and_round_trips():
    rng = np.random.default_rng(0)
    poses = rng.normal(3.0, 2.0, size=(500, 2 * POSE_DIM)).astype(np.float32)
    poses[:, 5] = 0.25  # a dimension that never varies is left unscaled
    oracle = OracleStandardisation.fit(poses, OBJECTS)
    z = oracle.apply(poses)
    np.testing.assert_allclose(z.mean(0), 0, atol=1e-5)
    np.testing.assert_allclose(np.delete(z.std(0), 5), 1, atol=1e-4)
    assert oracle.std[5] == 1 and np.all(z[:, 5] == 0)
    torch.testing.assert_close(oracle.apply(torch.from_numpy(poses)), torch.from_numpy(z))
    again = OracleStandardisation.from_metadata(json.loads(json.dumps(oracle.metadata())))
    np.testing.assert_array_equal(again.mean, oracle.mean)
    np.testing.assert_array_equal(again.std, oracle.std)
    assert again.objects == OBJECTS and again.dim == 2 * POSE_DIM


def test_artefact_keeps_the_oracle_and_rejects_a_bad_one(frontend_dir, tmp_path):
    artefact = FrontendArtefact.load(frontend_dir)
    assert artefact.oracle is None and "oracle" not in artefact.metadata()
    oracle = OracleStandardisation(OBJECTS, np.zeros(18, np.float32), np.full(18, 2.0, np.float32))
    artefact.oracle = oracle
    assert artefact.vision_dim == 18
    loaded = FrontendArtefact.load(artefact.save(tmp_path / "oracle"))
    np.testing.assert_array_equal(loaded.oracle.std, oracle.std)
    meta = json.loads((tmp_path / "oracle" / "frontend.json").read_text())
    meta["oracle"]["std"][3] = 0.0
    (tmp_path / "oracle" / "frontend.json").write_text(json.dumps(meta))
    with pytest.raises(FrontendArtefactError, match="oracle section.*std > 0"):
        FrontendArtefact.load(tmp_path / "oracle")


def test_a_policy_reads_the_oracle_front_end_only_when_built_for_its_size(frontend_dir, tmp_path):
    """The policy's processors take the oracle's poses as one block of visual features (the artefact's cameras are
    not read); a policy built for another size is refused with the flag that fixes it."""
    from lerobot_predvla.policies.common.processors import frontend_step
    from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

    artefact = FrontendArtefact.load(frontend_dir)
    artefact.oracle = OracleStandardisation(OBJECTS, np.zeros(18, np.float32), np.ones(18, np.float32))
    directory = artefact.save(tmp_path / "oracle")
    config = PredVLAConfig(frontend_dir=str(directory), vision_dim_per_camera=18, num_cameras=1, device="cpu")
    assert frontend_step(config).frontend().artefact.oracle is not None
    config.vision_dim_per_camera = 96  # the cameras' size: the oracle gives 18 numbers
    with pytest.raises(FrontendArtefactError, match="--policy.vision_dim_per_camera=18"):
        frontend_step(config)


def test_processor_standardises_the_environment_state_instead_of_encoding_cameras(frontend_dir):
    artefact = FrontendArtefact.load(frontend_dir)
    artefact.oracle = OracleStandardisation(OBJECTS, np.arange(18, dtype=np.float32), np.full(18, 2.0, np.float32))
    step = FrontendProcessorStep.from_artefact(artefact, refresh_interval=2)
    shapes = step.transform_features({PipelineFeatureType.OBSERVATION: {}})[PipelineFeatureType.OBSERVATION]
    assert shapes[OBS_VISION_FEATURES].shape == (18,)  # from the oracle, not the cameras' PCA
    step.reset()
    poses = torch.arange(36, dtype=torch.float32).reshape(2, 18)
    poses[1, 4] = float("nan")
    # No camera at all: an oracle policy does not look at images.
    out = step({TransitionKey.OBSERVATION: {OBS_ENV_STATE: poses},
                TransitionKey.COMPLEMENTARY_DATA: {"task": [SOUP, SOUP]}})
    vision = out[TransitionKey.OBSERVATION][OBS_VISION_FEATURES]
    torch.testing.assert_close(vision[0], (poses[0] - torch.arange(18.0)) / 2)
    assert torch.isnan(vision[1]).all()  # a non-finite pose masks the step, as a bad camera frame does
    # Between refresh ticks the last features are held, whatever the environment says.
    held = step({TransitionKey.OBSERVATION: {OBS_ENV_STATE: poses + 100},
                 TransitionKey.COMPLEMENTARY_DATA: {"task": [SOUP, SOUP]}})
    torch.testing.assert_close(held[TransitionKey.OBSERVATION][OBS_VISION_FEATURES], vision, equal_nan=True)
    step.reset()
    with pytest.raises(KeyError, match="--env.oracle=true"):
        step({TransitionKey.OBSERVATION: {"observation.state": torch.zeros(1, 9)},
              TransitionKey.COMPLEMENTARY_DATA: {"task": SOUP}})
    with pytest.raises(ValueError, match="12 values per step.*18"):
        step({TransitionKey.OBSERVATION: {OBS_ENV_STATE: torch.zeros(1, 12)},
              TransitionKey.COMPLEMENTARY_DATA: {"task": SOUP}})


@pytest.mark.simulator
def test_live_poses_equal_the_replayed_ones_and_are_the_gripper_frame_poses():
    """`--env.oracle=true` observes what `demo_object_poses` replays from the saved states: one definition."""
    from lerobot_predvla.sims.libero import env as libero_env
    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv
    from lerobot_predvla.sims.libero.oracle import object_poses

    cfg = PredVLALiberoEnv(task=SUITE, task_ids=[0], oracle=True)
    venv = cfg.create_envs(n_envs=1)[SUITE][0]
    obs, _ = venv.reset(seed=[0])
    inner = venv.envs[0].unwrapped._env
    objects = venv.envs[0].unwrapped.oracle_objects
    assert objects == OBJECTS[SOUP]
    replay = libero_env.make_env(libero_env.task_spec(SUITE, 0))
    replay.reset()
    for _ in range(4):
        live = obs[OBS_ENV_STATE.removeprefix("observation.")][0]
        assert live.shape == (2 * POSE_DIM,)
        np.testing.assert_allclose(live, object_poses(replay.regenerate_obs_from_state(inner.get_sim_state()), objects),
                                   atol=1e-6)
        # The soup's position in the gripper's frame: R_eef^T (p_soup - p_eef), from the simulator's bodies.
        sim, robosuite_env = inner.env.sim, inner.env
        p_soup = sim.data.body_xpos[robosuite_env.obj_body_id["alphabet_soup_1"]]
        eef = robosuite_env._get_observations(force_update=True)
        r_eef = Rotation.from_quat(eef["robot0_eef_quat"]).as_matrix()
        np.testing.assert_allclose(live[:3], r_eef.T @ (p_soup - eef["robot0_eef_pos"]), atol=1e-5)
        obs, *_ = venv.step(np.array([[0.0, 0.0, -0.5, 0.0, 0.0, 0.0, -1.0]], dtype=np.float32))
    venv.close()
    replay.close()


@pytest.fixture(scope="module")
def expert_hdf5(tmp_path_factory):
    """Five real scripted-expert episodes of libero_object task 0 (physics only) in LIBERO's hdf5 layout: the real
    simulator states; the images and proprioception are generated (the oracle reads only the states)."""
    from lerobot_predvla.sims.libero import env as libero_env
    from lerobot_predvla.sims.libero.rollout import run_episode

    spec = libero_env.task_spec(SUITE, 0)
    env = libero_env.make_env(spec)
    episodes = [run_episode(env, seed=seed, max_steps=280) for seed in range(3, 8)]
    env.close()
    assert all(episode.success for episode in episodes), [episode.note for episode in episodes]
    root = tmp_path_factory.mktemp("hdf5")
    path = root / SUITE / f"{spec.name}_demo.hdf5"
    write_libero_file(path, spec.language, [len(episode.actions) for episode in episodes], seed=4)
    with h5py.File(path, "r+") as f:
        for i, episode in enumerate(episodes):
            del f[f"data/demo_{i}/states"]
            f[f"data/demo_{i}/states"] = episode.states
    return root, spec


@pytest.mark.simulator
def test_convert_oracle_writes_standardised_poses_and_no_camera(expert_hdf5, frontend_dir, tmp_path):
    """`predvla convert --oracle`: the poses replayed from each demonstration's saved states, standardised."""
    from lerobot_predvla.data.libero_hdf5 import scan_file
    from lerobot_predvla.sims.libero import env as libero_env
    from lerobot_predvla.sims.libero.oracle import demo_object_poses
    from research.oracle_probe import run_probe

    root, spec = expert_hdf5
    out = tmp_path / "dataset"
    argv = ["convert", "--hdf5-root", str(root), "--suite", SUITE, "--frontend", str(frontend_dir),
            "--out", str(out), "--oracle"]
    assert run_cli(argv) == 0
    dataset = LeRobotDataset("local/oracle", root=out)
    assert not dataset.meta.camera_keys
    vision = np.stack(dataset.hf_dataset.with_format("numpy")[:][OBS_VISION_FEATURES])
    assert vision.shape == (dataset.meta.total_frames, 2 * POSE_DIM)
    np.testing.assert_allclose(vision.mean(0), 0, atol=1e-3)  # standardised on these demonstrations
    artefact = FrontendArtefact.load(out / FRONTEND_META_DIR)
    assert artefact.oracle.objects == {spec.language: OBJECTS[SOUP]}
    env = libero_env.make_env(spec)
    env.reset()
    first = scan_file(root / SUITE / f"{spec.name}_demo.hdf5")[0]
    raw = demo_object_poses(env, first, OBJECTS[SOUP])
    env.close()
    np.testing.assert_allclose(vision[: first.num_frames], artefact.oracle.apply(raw), atol=1e-5)
    # The soup comes within a few centimetres of the gripper (the grasp) from 10 cm or more away.
    distance = np.linalg.norm(raw[:, :3], axis=1)
    assert distance[0] > 0.1 and distance.min() < 0.05
    # The probe finds the poses in "visual features" that are the poses themselves, whatever proprioception says.
    result = run_probe(root, SUITE, out)
    assert result.demonstrations == 5 and result.frames == dataset.meta.total_frames
    assert result.r2_vision["all"] > 0.99 and result.partial_r2_vision["all"] > 0.95
    assert result.r2_proprio["all"] < result.r2_both["all"]
    argv = ["convert", "--dataset-root", str(out), "--frontend", str(frontend_dir), "--out", str(tmp_path / "x"),
            "--oracle"]
    assert run_cli(argv) == 2  # a LeRobot dataset has no simulator states

    # PredVLA trains on it (the poses are one block of visual features) and lerobot-eval drives it from the live
    # poses with error regression, no camera read.
    train = [str(BIN / "lerobot-train"), "--policy.type=predvla", "--dataset.repo_id=local/oracle",
             f"--dataset.root={out}", "--policy.push_to_hub=false", "--policy.device=cpu", "--num_workers=0",
             "--steps=2", "--save_freq=2", "--batch_size=2", "--wandb.enable=false", "--policy.sequence_length=16",
             "--policy.er_window=4", "--policy.er_iterations=2"]
    refused = subprocess.run([*train, f"--output_dir={tmp_path / 'refused'}"], capture_output=True, text=True)
    assert refused.returncode != 0 and "--policy.vision_dim_per_camera" in refused.stderr
    run([*train, f"--policy.vision_dim_per_camera={2 * POSE_DIM}", f"--output_dir={tmp_path / 'train'}"])
    checkpoint = tmp_path / "train" / "checkpoints" / "000002" / "pretrained_model"
    run([str(BIN / "lerobot-eval"), f"--policy.path={checkpoint}", "--env.type=predvla_libero", f"--env.task={SUITE}",
         "--env.task_ids=[0]", "--env.episode_length=6", "--env.oracle=true", "--eval.n_episodes=1",
         "--eval.batch_size=1", "--eval.use_async_envs=false", "--policy.device=cpu",
         f"--output_dir={tmp_path / 'eval'}"])
    info = json.loads((tmp_path / "eval" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1
    faults = info["predvla_faults"]
    assert faults["nonfinite_actions"] == 0 and faults["policy"]["fallback_actions"] == 0, faults
