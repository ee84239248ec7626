"""Camera images and proprioception of a saved episode, by replaying its states in a camera env."""

import numpy as np

from lerobot_predvla.columns import SIM_CAMERAS
from lerobot_predvla.sims.libero.env import set_fixture_poses
from lerobot_predvla.sims.libero.rollout import Episode


def set_cameras_enabled(render_env, enabled: bool) -> None:
    """Switch the camera observables (the renders) of a camera env on or off."""
    for camera in SIM_CAMERAS.values():
        render_env.env.modify_observable(f"{camera}_image", "enabled", enabled)


def replay_observations(render_env, episode: Episode, render_interval: int = 1) -> dict[str, np.ndarray]:
    """Per-step observations in LIBERO's dataset naming; images stay upside down as rendered.

    With `render_interval` k > 1 the cameras render at steps 0, k, 2k, ... and the steps in between repeat
    the last images: PredVLA consumes a fresh image every `visual_refresh_interval` steps from the
    episode start (Table 1: 4), so k = 4 loses nothing it reads and renders 4x less.
    """
    import robosuite.utils.transform_utils as T  # after env.py has chosen MUJOCO_GL

    set_fixture_poses(render_env, episode.fixtures)
    keys = ("agentview_rgb", "eye_in_hand_rgb", "joint_states", "gripper_states", "ee_states", "robot_states")
    out: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    images = None
    for t, state in enumerate(episode.states):
        render = t % render_interval == 0
        if render_interval > 1:
            set_cameras_enabled(render_env, render)
        obs = render_env.regenerate_obs_from_state(state)
        if render:
            images = obs["agentview_image"], obs["robot0_eye_in_hand_image"]
        out["agentview_rgb"].append(images[0])
        out["eye_in_hand_rgb"].append(images[1])
        out["joint_states"].append(obs["robot0_joint_pos"])
        out["gripper_states"].append(obs["robot0_gripper_qpos"])
        out["ee_states"].append(np.hstack([obs["robot0_eef_pos"], T.quat2axisangle(obs["robot0_eef_quat"])]))
        out["robot_states"].append(render_env.env.get_robot_state_vector(obs))
    if render_interval > 1:
        set_cameras_enabled(render_env, True)
    arrays = {k: np.stack(v) for k, v in out.items()}
    arrays["ee_pos"], arrays["ee_ori"] = arrays["ee_states"][:, :3], arrays["ee_states"][:, 3:]
    return arrays
