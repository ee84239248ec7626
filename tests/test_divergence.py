"""`python -m research.divergence`: the open loop against demonstrations from their own starts.

The helpers on synthetic arrays; then the real command on the simulator (physics only): two scripted-expert
episodes written with the repository's demo writer (images left black: the command reads none), the shipped
Table 2 checkpoint, one demonstration and a 30-step cap.
"""

import json

import numpy as np
import pytest

from research.divergence import simulation as dv

CHECKPOINT = "checkpoints/predvla_libero_object_table2"
SUITE, TASK_ID = "libero_object", 0


def synthetic_demo(n=100, close=40, lift_at=50, top_at=70, reopen=90):
    actions = np.zeros((n, 7))
    actions[:, 6] = -1.0
    actions[close:reopen, 6] = 1.0
    z = np.full(n, 0.02)
    z[:close] = np.linspace(0.3, 0.02, close)
    z[lift_at:top_at] = np.linspace(0.03, 0.25, top_at - lift_at)
    z[top_at:] = 0.25
    ee = np.zeros((n, 3))
    ee[:, 2] = z
    return actions, ee


def test_phases_follow_the_gripper_command_and_the_height():
    actions, ee = synthetic_demo()
    bounds = dv.phase_bounds(actions, ee)
    assert bounds["approach"] == 0 and bounds["grasp"] == 40 and bounds["release"] == 90
    assert 50 <= bounds["lift"] <= 51  # the first step 1 cm above where the gripper closed
    assert 66 <= bounds["carry/place"] <= 70  # within 1 cm of the top
    assert dv.phase_of(0, bounds) == "approach" and dv.phase_of(45, bounds) == "grasp"
    assert dv.phase_of(95, bounds) == "release"
    never = actions.copy()
    never[:, 6] = -1.0
    assert dv.phase_bounds(never, ee)["grasp"] == 100  # never closes: the approach is the whole episode


def test_first_run_and_envelope():
    assert dv.first_run(np.array([0, 1, 0, 1, 1, 1, 0], bool), 3) == 3
    assert dv.first_run(np.array([0, 1, 0], bool), 2) == -1
    rng = np.random.default_rng(0)
    demos = [rng.uniform(-0.5, 0.5, (20, 7)) for _ in range(5)]
    inside = np.mean(demos, axis=0)
    out = dv.offline_actions(inside, demos)
    assert out["inside_fraction_all_dims"] == 1.0 and out["first_exit_step_any_dim"] == -1
    leaving = inside.copy()
    leaving[12:, 5] = 0.9  # one dimension leaves every demo's range from step 12 on
    out = dv.offline_actions(leaving, demos)
    assert out["first_exit_step_per_dim"]["5"] == 12 and out["first_exit_step_any_dim"] == 12
    assert out["first_exit_step_per_dim"]["0"] == -1
    np.testing.assert_allclose(out["mse_vs_mean"][:12], 0.0, atol=1e-12)
    assert (out["demo_spread"] > 0).all()


def test_orientation_error_of_equal_and_turned_orientations():
    rotvec = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]])
    same = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, np.sin(0.25), np.cos(0.25)]])
    np.testing.assert_allclose(dv.orientation_error(same, rotvec), 0.0, atol=1e-6)
    turned = np.array([[0.0, 0.0, np.sin(0.15), np.cos(0.15)]])  # 0.3 rad about z
    np.testing.assert_allclose(dv.orientation_error(turned, rotvec[:1]), 0.3, atol=1e-6)


@pytest.fixture(scope="module")
def demo_root(tmp_path_factory):
    try:
        from lerobot_predvla.sims.libero import env as env_mod

        spec = env_mod.task_spec(SUITE, TASK_ID)
    except (RuntimeError, ImportError) as err:
        pytest.fail(f"LIBERO is not installed: run `make libero` ({err})")
    import robosuite.utils.transform_utils as T  # after env.py has chosen MUJOCO_GL

    from lerobot_predvla.sims.libero.hdf5_layout import OBS_KEYS, task_file, write_task_file
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(spec)
    demos = []
    for seed in (7, 1000):  # seeds the expert solves (test_libero_demos.py)
        episode = run_episode(env, seed=seed, max_steps=280)
        assert episode.success, episode.note
        obs = {k: [] for k in ("joint_states", "gripper_states", "ee_pos", "ee_ori")}
        for state in episode.states:
            o = env.regenerate_obs_from_state(state)
            obs["joint_states"].append(o["robot0_joint_pos"])
            obs["gripper_states"].append(o["robot0_gripper_qpos"])
            obs["ee_pos"].append(o["robot0_eef_pos"])
            obs["ee_ori"].append(T.quat2axisangle(o["robot0_eef_quat"]))
        arrays = {k: np.stack(v) for k, v in obs.items()}
        arrays["ee_states"] = np.hstack([arrays["ee_pos"], arrays["ee_ori"]])
        n = len(episode.actions)
        for key in ("agentview_rgb", "eye_in_hand_rgb"):
            arrays[key] = np.zeros((n, *OBS_KEYS[key]), np.uint8)  # never read by the command
        arrays["robot_states"] = np.zeros((n, 9))
        demos.append({**arrays, "actions": episode.actions, "states": episode.states,
                      "model_file": episode.model_xml})
    env.close()
    root = tmp_path_factory.mktemp("divergence")
    write_task_file(task_file(root / "hdf5", spec), {"problem_info": json.dumps({"language_instruction":
                                                                                spec.language})}, demos)
    return root


@pytest.mark.simulator
def test_divergence_command_on_the_simulator(demo_root):
    from research.divergence.__main__ import main

    out = demo_root / "out"
    assert main(["--checkpoint", CHECKPOINT, "--hdf5-root", str(demo_root / "hdf5"), "--tasks",
                 str(TASK_ID), "--demos", "1", "--cap", "30", "--out", str(out)]) == 0
    assert (out / f"task{TASK_ID}.png").stat().st_size > 10_000
    report = json.loads((out / "divergence.json").read_text())
    task = report["tasks"][str(TASK_ID)]
    assert task["demos_in_file"] == 2 and task["demos_simulated"] == [0]
    row = task["demos"][0]
    assert row["blind_plan_demo"] == 1
    # The demonstration's own actions from its own first state reproduce it (the floor of every distance).
    assert row["replay"]["ee_max_m"] < 0.005 and row["replay"]["steps_compared"] == row["length"] > 30
    for name in ("open_loop", "open_loop_demo_rotation", "blind_plan"):
        assert row[name]["steps_compared"] == 30
        assert set(row[name]["separation"]) == {"1cm", "2cm", "5cm", "10cm"}
    assert task["offline"]["horizon"] == 30
    phases = list(row["phases"].values())
    assert phases == sorted(phases)
    assert (out / "summary.md").read_text().count(f"| {TASK_ID} |") >= 3


@pytest.mark.simulator
def test_open_loop_actions_are_what_select_action_gives_in_exact_open_loop():
    """The command's actions are the policy's own acting path with er_iterations=0, unnormalised."""
    import torch

    open_loop = dv.OpenLoop(CHECKPOINT)
    instruction = "pick up the alphabet soup and place it in the basket"
    normalised = open_loop.normalised(instruction, 8)
    policy, language = open_loop.policy, open_loop.language(instruction)
    policy.reset()
    acted = torch.stack([policy.select_action({"observation.language_features": language,
                                               "observation.vision_features": torch.randn(1, 192),
                                               "observation.state": torch.randn(1, 9)})[0] for _ in range(8)])
    torch.testing.assert_close(acted, normalised, atol=1e-5, rtol=0)
    raw = open_loop.actions(instruction, 8)
    low, high = (open_loop.postprocessor.steps[0]._tensor_stats["action"][k].numpy() for k in ("min", "max"))
    np.testing.assert_allclose(raw, (normalised.numpy() + 1) / 2 * (high - low) + low, atol=1e-5)


def test_mean_plan_is_the_time_aligned_mean_and_demo_is_the_demonstration():
    from research.divergence.mean_plan import task_plans

    short, long = np.full((3, 7), 1.0), np.full((5, 7), 3.0)
    plans = task_plans([short, long], demo=1)
    np.testing.assert_allclose(plans["mean"][:3], 2.0)  # both run: their mean
    np.testing.assert_allclose(plans["mean"][3:], 3.0)  # only the longer one (half of them) still runs
    assert np.array_equal(plans["demo"], long)
    with pytest.raises(ValueError, match="--demo 2"):
        task_plans([short, long], demo=2)


@pytest.mark.simulator
def test_mean_plan_command_on_the_simulator(demo_root):
    from research.divergence.mean_plan import main

    out = demo_root / "mean_plan"
    assert main(["--hdf5-root", str(demo_root / "hdf5"), "--tasks", str(TASK_ID), "--states", "0-1", "--cap", "300",
                 "--out", str(out)]) == 0
    task = json.loads((out / "mean_plan.json").read_text())["tasks"][str(TASK_ID)]
    assert task["demonstrations"] == 2 and task["plan_lengths"]["mean"] == task["demo_lengths"][1]
    closes = task["demo_close_steps"]
    for name in ("mean", "demo"):
        episodes = task["episodes"][name]
        assert [e["state"] for e in episodes] == [0, 1]
        for e in episodes:
            assert len(e["offset_m"]) == 3 and all(np.isfinite(e["offset_m"]))
            assert e["success_step"] is None or 0 < e["success_step"] <= 300
    assert min(closes) <= task["episodes"]["mean"][0]["close"] <= max(closes)
    assert task["episodes"]["demo"][0]["close"] == closes[0]
    assert task["summary"]["mean"]["episodes"] == 2
    assert (out / "mean_plan.md").read_text().count(f"| {TASK_ID} |") == 2
    assert (out / "mean_plan.png").stat().st_size > 5_000
