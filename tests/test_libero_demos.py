"""Real LIBERO check: one scripted-expert episode, rendered by replay, written and reloaded as hdf5.

Needs the simulator (`make libero`, which `make test` runs first); without it the test fails.
"""

import dataclasses
import json
import os
import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

pytestmark = pytest.mark.simulator

SUITE, TASK_ID, SEED = "libero_object", 0, 7


@pytest.fixture(scope="module")
def libero():
    try:
        from lerobot_predvla.sims.libero import env
        from lerobot_predvla.sims.libero.env import task_spec

        spec = task_spec(SUITE, TASK_ID)
    except (RuntimeError, ImportError) as err:
        pytest.fail(f"LIBERO is not installed: run `make libero` ({err})")
    return env, spec


def test_expert_episode_to_hdf5(libero, tmp_path):
    env_mod, spec = libero
    from lerobot_predvla.sims.libero.hdf5_layout import check_task_file, file_attrs, task_file, write_task_file
    from lerobot_predvla.sims.libero.render import replay_observations
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(spec)
    episode = run_episode(env, seed=SEED, max_steps=280)
    env.close()
    assert episode.success, f"expert failed on {spec.name}: {episode.note}"
    assert 50 < len(episode.actions) < 280
    assert np.abs(episode.actions).max() <= 1.0

    render_env = env_mod.make_env(spec, render=True)
    env_mod.random_reset(render_env, 0)
    obs = replay_observations(render_env, episode)
    # Sparse rendering (`--render-interval 4`): steps 0, 4, 8 as before, the others repeat the last images.
    head = dataclasses.replace(episode, states=episode.states[:9], actions=episode.actions[:9])
    sparse = replay_observations(render_env, head, render_interval=4)
    for t in range(9):
        np.testing.assert_array_equal(sparse["agentview_rgb"][t], obs["agentview_rgb"][t - t % 4])
        np.testing.assert_array_equal(sparse["eye_in_hand_rgb"][t], obs["eye_in_hand_rgb"][t - t % 4])
    np.testing.assert_array_equal(sparse["joint_states"], obs["joint_states"][:9])
    # Replaying the last saved state and the last action reproduces the success.
    render_env.regenerate_obs_from_state(episode.states[-1])
    render_env.step(episode.actions[-1])
    assert render_env.check_success()
    attrs = file_attrs(spec, render_env)
    render_env.close()

    path = task_file(tmp_path, spec)
    demo = {**obs, "actions": episode.actions, "states": episode.states, "model_file": episode.model_xml}
    write_task_file(path, attrs, [demo, demo])
    assert path.name == f"{spec.name}_demo.hdf5" and path.parent.name == SUITE
    assert not list(path.parent.glob("*.tmp"))
    assert check_task_file(path) == 2

    n = len(episode.actions)
    with h5py.File(path, "r") as f:
        data = f["data"]
        info = json.loads(data.attrs["problem_info"])
        assert info["language_instruction"] == spec.language
        assert data.attrs["bddl_file_content"] == spec.bddl_file.read_text()
        assert json.loads(data.attrs["env_args"])["env_kwargs"]["controller_configs"]["type"] == "OSC_POSE"
        assert data.attrs["total"] == 2 * n
        d0 = data["demo_0"]
        np.testing.assert_array_equal(d0["actions"][()], episode.actions)
        np.testing.assert_array_equal(d0.attrs["init_state"], episode.states[0])
        assert d0["dones"][-1] == 1 and d0["rewards"][()].sum() == 1
        img = d0["obs/agentview_rgb"][0]
        assert img.shape == (128, 128, 3) and img.std() > 10
        # Upside down like the originals: the wrist camera's dark gripper body lies in the top rows.
        wrist = d0["obs/eye_in_hand_rgb"][0].astype(float)
        assert wrist[:12].mean() < wrist[-12:].mean() - 10
        np.testing.assert_allclose(d0["obs/ee_pos"][()], d0["obs/ee_states"][:, :3])
        assert d0["obs/gripper_states"][0, 0] > 0.03  # gripper starts open
        assert "<mujoco" in d0.attrs["model_file"]


def test_initial_joint_noise_spreads_the_arm_like_the_official_init_states(libero):
    """`init_noise` = robosuite's default starts the arm as the benchmark's init states do; 0 is one fixed pose;
    the seed fixes the noise. Objects are placed alike either way."""
    env_mod, spec = libero
    from lerobot_predvla.sims.libero.start_spread import start_spread

    fixed = start_spread(SUITE, TASK_ID, n=10, init_noise=0.0)
    noisy = start_spread(SUITE, TASK_ID, n=10, init_noise=env_mod.OFFICIAL_INIT_NOISE)
    assert fixed["randomised"]["joint_std"] < 1e-9
    assert 0.5 < noisy["randomised"]["joint_std"] / noisy["official"]["joint_std"] < 2.0, noisy
    for name, std in fixed["official"]["object_std"].items():
        assert abs(std - fixed["randomised"]["object_std"][name]) < 0.005, (name, fixed)
    env = env_mod.make_env(spec, init_noise=env_mod.OFFICIAL_INIT_NOISE)
    robot = env.env.robots[0]
    starts = []
    for _ in range(2):
        env_mod.random_reset(env, 3)
        starts.append(env.env.sim.data.qpos[robot._ref_joint_pos_indexes].copy())
    env.close()
    np.testing.assert_array_equal(*starts)


def test_a_stale_config_names_the_file_and_key(tmp_path, monkeypatch):
    from lerobot_predvla.sims.libero.env import task_spec

    (tmp_path / "config.yaml").write_text(f"bddl_files: {tmp_path / 'gone'}\n")
    monkeypatch.setenv("LIBERO_CONFIG_PATH", str(tmp_path))
    with pytest.raises(RuntimeError, match=r"config.yaml: `bddl_files` is .*gone.*make libero"):
        task_spec(SUITE, TASK_ID)
    # The eval env (what lerobot-eval imports) checks it too, before LIBERO reads it deep inside a reset.
    out = subprocess.run([sys.executable, "-c", "import lerobot_predvla.sims.libero.predvla_libero"],
                         capture_output=True, text=True, env={**os.environ, "LIBERO_CONFIG_PATH": str(tmp_path)})
    assert out.returncode != 0
    assert re.search(r"config.yaml: `bddl_files` is .*gone.*make libero", out.stderr.splitlines()[-1])


def test_wrist_centre_half_turn_keeps_one_wrist_branch_under_start_noise(libero):
    """Salad dressing with the official init states' arm noise: the 'nearest' half turn lets the start noise pick
    the wrist branch (two resets end half a turn apart); 'wrist_centre' ends both on one branch. All succeed."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec(SUITE, 2), init_noise=env_mod.OFFICIAL_INIT_NOISE)
    wrist = env.env.robots[0].robot_joints[-1]
    ends = {}
    for rule in ("nearest", "wrist_centre"):
        for seed in (1000, 1002):
            episode = run_episode(env, seed, max_steps=280, half_turn=rule)
            assert episode.success, (rule, seed, episode.note)
            ends[rule, seed] = env.sim.data.qpos[env.sim.model.get_joint_qpos_addr(wrist)]
    env.close()
    assert abs(ends["nearest", 1000] - ends["nearest", 1002]) > 2.5, ends  # about pi apart
    assert abs(ends["wrist_centre", 1000] - ends["wrist_centre", 1002]) < 0.3, ends


def test_hold_steps_record_the_arm_waiting_after_success(libero):
    """`--hold-steps`: the same episode, then idle steps (arm still, gripper open) with the object staying put."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.rollout import IDLE, run_episode

    env = env_mod.make_env(env_mod.task_spec(SUITE, 0))
    plain = run_episode(env, 1000, max_steps=280)
    held = run_episode(env, 1000, max_steps=280, hold_steps=6)
    assert plain.success and held.success and env.check_success()  # still in the basket after the holds
    env.close()
    n = len(plain.actions)
    assert held.actions.shape == (n + 6, 7) and np.array_equal(held.actions[:n], plain.actions)
    assert np.array_equal(held.actions[n:], np.tile(IDLE, (6, 1))) and len(held.states) == n + 6


def test_expert_success_from_the_official_init_states(libero):
    """`predvla demos --no-render --official-init-states` measures the expert where the policies are evaluated:
    attempt k starts from official init state k (the arm's joint noise included). Recording from them is refused."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.rollout import run_episode

    cli = [sys.executable, "-m", "lerobot_predvla.cli.main", "demos", "--suite", SUITE, "--tasks", "2",
           "--per-task", "2", "--max-attempts", "2", "--official-init-states"]
    out = subprocess.run([*cli, "--no-render"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "official init states" in out.stdout
    assert re.search(r"^\s+2\s+2\s+2\s+100%", out.stdout, re.M), out.stdout
    refused = subprocess.run([*cli, "--out", "unused"], capture_output=True, text=True)
    assert refused.returncode != 0 and "--no-render" in refused.stderr

    env = env_mod.make_env(env_mod.task_spec(SUITE, 2))
    states = env_mod.official_init_states(SUITE, 2)
    episode = run_episode(env, 0, max_steps=280, init_state=states[1])
    env.close()
    assert episode.success, episode.note
    # The start is the init state's, not a seeded randomised reset's: another seed starts identically.
    env = env_mod.make_env(env_mod.task_spec(SUITE, 2))
    again = run_episode(env, 99, max_steps=1, init_state=states[1])
    randomised = [run_episode(env, seed, max_steps=1).states[0] for seed in (0, 99)]
    env.close()
    np.testing.assert_array_equal(again.states[0], episode.states[0])
    assert np.abs(randomised[0] - randomised[1]).max() > 1e-3


def test_expert_turns_on_the_stove(libero):
    """An articulated goal (`Turnon`): the knob is grasped and twisted from a randomised reset, physics only."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_goal", 7))  # turn_on_the_stove
    episode = run_episode(env, seed=3, max_steps=300)
    env.close()
    assert episode.success, episode.note
    assert len(episode.actions) < 150


def test_expert_pushes_the_plate_around_the_cream_cheese(libero):
    """A flat object is pushed, not picked, along an L-shaped path that keeps the plate clear of the cream
    cheese standing between it and the stove's front region, then into that region (physics only)."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import IDLE, SETTLE_STEPS, run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_goal", 5))  # push_the_plate_to_the_front_of_the_stove
    env_mod.random_reset(env, 1)
    for _ in range(SETTLE_STEPS):  # objects spawn above their support
        env.step(IDLE)
    expert = ScriptedExpert(env)
    start, corner, goal = expert._push_plan("plate_1", "main_table_stove_front_region")
    assert np.allclose(corner, [start[0], goal[1]])  # first along y beside the cheese, then along x
    assert expert._path_clearance("plate_1", expert.view.box("plate_1").long / 2, [start, goal]) < 0
    episode = run_episode(env, seed=1, max_steps=300)
    env.close()
    assert episode.success, episode.note


def test_expert_leans_its_rim_grasp_under_the_open_drawer(libero):
    """Open the top drawer, then put the bowl inside: the open drawer overhangs the bowl, so the rim grasp
    leans along the rim to keep the hand off it (upright, the hand hits the drawer: 1/10 before the lean)."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_goal", 3))  # open_the_top_drawer_and_put_the_bowl_inside
    env_mod.random_reset(env, 2)
    expert = ScriptedExpert(env)
    _, upright = expert._rim_grasp("akita_black_bowl_1")
    assert np.allclose(upright, [0, 0, -1])  # drawer closed: nothing above the bowl
    joint = expert.view.joints("wooden_cabinet_1_top_region")[0]
    env.sim.data.qpos[env.sim.model.get_joint_qpos_addr(joint)] = -0.15  # open (LIBERO: below -0.14)
    env.sim.forward()
    _, leaning = expert._rim_grasp("akita_black_bowl_1")
    assert leaning[2] > -0.95  # tilted away from vertical by more than ~18 degrees
    episode = run_episode(env, seed=2, max_steps=300)
    env.close()
    assert episode.success, episode.note


def test_expert_swings_the_microwave_door_shut(libero):
    """A hinged door's `Close` (libero_10 task 9's second predicate): the door is pushed round its hinge
    from the trailing face until LIBERO's own predicate holds."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import IDLE, SETTLE_STEPS

    env = env_mod.make_env(env_mod.task_spec("libero_10", 9))  # ..._mug_in_the_microwave_and_close_it
    env_mod.random_reset(env, 0)
    for _ in range(SETTLE_STEPS):
        env.step(IDLE)
    expert = ScriptedExpert(env)
    assert not expert.view.holds("close", "microwave_1")  # the scene starts with the door open
    steps = 0
    for action in expert._articulate("microwave_1", "close"):
        env.step(action)
        steps += 1
    assert expert.view.holds("close", "microwave_1"), f"door at {expert.view.joint_qpos('microwave_1_microjoint')}"
    env.close()
    assert steps < 250


def test_expert_grasps_a_moka_pot_by_its_handle(libero):
    """A wide object with a thin part reaching out (a moka pot's handle) is grasped there, fingers across it;
    a bowl has no handle and keeps the rim grasp. Then the pot is picked and put on the stove."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import run_episode

    bowl_env = env_mod.make_env(env_mod.task_spec("libero_goal", 1))  # put_the_bowl_on_the_stove
    env_mod.random_reset(bowl_env, 0)
    assert ScriptedExpert(bowl_env)._handle("akita_black_bowl_1") is None
    bowl_env.close()

    env = env_mod.make_env(env_mod.task_spec("libero_10", 2))  # turn_on_the_stove_and_put_the_moka_pot_on_it
    env_mod.random_reset(env, 0)
    expert = ScriptedExpert(env)
    handle = expert._handle("moka_pot_1")
    origin = expert.view.body_pos("moka_pot_1")
    assert handle is not None and np.linalg.norm(handle[:2] - origin[:2]) > 0.06
    pos, finger = expert._grasp_pose("moka_pot_1")
    assert np.allclose(pos, handle) and abs(finger @ (handle[:2] - origin[:2])) < 1e-6  # across the handle
    episode = run_episode(env, seed=0, max_steps=520)
    env.close()
    assert episode.success, episode.note


def test_expert_puts_each_mug_on_its_plate_by_body_origin(libero):
    """LIBERO's `On` between two objects compares body origins (within 3 cm), and a mug held by its rim hangs
    tilted, its box centre ~2 cm off its origin (at its bottom): the origin is carried over the plate's
    (0/10 when box centres were aligned)."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_10", 4))  # white mug on the left plate, yellow one right
    env_mod.random_reset(env, 0)
    expert = ScriptedExpert(env)
    target = expert._target("on", "plate_2", "white_yellow_mug_1")
    assert target.by_origin and np.allclose(target.xy, expert.view.body_pos("plate_2")[:2])
    episode = run_episode(env, seed=0, max_steps=520)
    env.close()
    assert episode.success, episode.note


def test_expert_puts_the_bowl_in_the_bottom_drawer_and_pushes_it_shut(libero):
    """libero_10 task 3: between the open bottom drawer's front and the cabinet over its back there is less room
    than the bowl needs until the drawer is pushed out to its stop (from inside); the bowl is lowered there, then
    the drawer is pushed shut by its handle (0/10 before, grasping the sideways handle to close it; 9/10 with the
    push alone, the bowl dropped from higher up landing tilted once and jamming the drawer)."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import IDLE, SETTLE_STEPS, run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_10", 3))  # ..._black_bowl_in_the_bottom_drawer_..._and_close_it
    env_mod.random_reset(env, 0)
    for _ in range(SETTLE_STEPS):
        env.step(IDLE)
    expert = ScriptedExpert(env)
    region, joint = "white_cabinet_1_bottom_region", "white_cabinet_1_bottom_level"
    assert expert._drawer_spot("akita_black_bowl_1", region)[1] < 0
    env.sim.data.qpos[env.sim.model.get_joint_qpos_addr(joint)] = expert.view.joint_range(joint)[0]  # open stop
    env.sim.forward()
    assert expert._drawer_spot("akita_black_bowl_1", region)[1] > 0
    episode = run_episode(env, seed=0, max_steps=520)
    env.close()
    assert episode.success, episode.note


def test_expert_slides_the_mug_into_the_microwave(libero):
    """libero_10 task 9: the microwave's cavity has a roof (lowering the mug from above put it on top, 0/10), so
    the mug is grasped by its handle, which faces the open side, the gripper leaning back to keep the hand
    outside, then slid in just above the floor; the door is swung shut afterwards."""
    env_mod, _ = libero
    from lerobot_predvla.sims.libero.expert import ScriptedExpert
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec("libero_10", 9))  # ..._mug_in_the_microwave_and_close_it
    env_mod.random_reset(env, 0)
    expert = ScriptedExpert(env)
    assert np.allclose(expert._opening("microwave_1_heating_region"), [0, -1])  # opens towards -y
    basket_env = env_mod.make_env(env_mod.task_spec("libero_object", 0))
    env_mod.random_reset(basket_env, 0)
    assert ScriptedExpert(basket_env)._opening("basket_1_contain_region") is None  # no roof: lowered from above
    basket_env.close()
    episode = run_episode(env, seed=0, max_steps=520)
    env.close()
    assert episode.success, episode.note


def test_demo_start_spread_reads_the_demonstrations_first_states(libero, tmp_path):
    """Demonstrations that start exactly at the official init states spread exactly as those do; a missing task file
    is named."""
    env_mod, spec = libero
    from lerobot_predvla.sims.libero.hdf5_layout import task_file
    from lerobot_predvla.sims.libero.start_spread import demo_start_spread, main

    path = task_file(tmp_path, spec)
    path.parent.mkdir(parents=True)
    with h5py.File(path, "w") as f:
        for i, state in enumerate(env_mod.official_init_states(SUITE, TASK_ID)):
            f.create_dataset(f"data/demo_{i}/states", data=np.stack([state, state]))
    spread = demo_start_spread(tmp_path, SUITE, TASK_ID)
    assert spread["demonstrations"] == spread["official"]
    assert spread["official"]["starts"] == 50 and spread["official"]["joint_std"] > 0.005
    assert main(["--suite", SUITE, "--demos", str(tmp_path / "elsewhere")]) == 2


def test_demos_refuses_a_task_the_suite_does_not_have_before_recording_any(libero, tmp_path):
    from lerobot_predvla.cli.main import main

    with pytest.raises(SystemExit, match=r"--tasks \[10\]: libero_object has tasks 0-9"):
        main(["demos", "--suite", SUITE, "--tasks", "0,10", "--per-task", "1", "--out", str(tmp_path)])
    assert not any(tmp_path.iterdir())
