"""Camera images and proprioception of a saved episode, by replaying its states in a camera env."""

import numpy as np

from lerobot_predvla.libero.env import set_fixture_poses
from lerobot_predvla.libero.rollout import Episode


def replay_observations(render_env, episode: Episode) -> dict[str, np.ndarray]:
    """Per-step observations in LIBERO's dataset naming; images stay upside down as rendered."""
    import robosuite.utils.transform_utils as T  # after env.py has chosen MUJOCO_GL

    set_fixture_poses(render_env, episode.fixtures)
    keys = ("agentview_rgb", "eye_in_hand_rgb", "joint_states", "gripper_states", "ee_states", "robot_states")
    out: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for state in episode.states:
        obs = render_env.regenerate_obs_from_state(state)
        out["agentview_rgb"].append(obs["agentview_image"])
        out["eye_in_hand_rgb"].append(obs["robot0_eye_in_hand_image"])
        out["joint_states"].append(obs["robot0_joint_pos"])
        out["gripper_states"].append(obs["robot0_gripper_qpos"])
        out["ee_states"].append(np.hstack([obs["robot0_eef_pos"], T.quat2axisangle(obs["robot0_eef_quat"])]))
        out["robot_states"].append(render_env.env.get_robot_state_vector(obs))
    arrays = {k: np.stack(v) for k, v in out.items()}
    arrays["ee_pos"], arrays["ee_ori"] = arrays["ee_states"][:, :3], arrays["ee_states"][:, 3:]
    return arrays
