"""The `predvla_libero` gym env: LeRobot's LiberoEnv with end-of-step observations and sparse rendering."""

from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.envs.libero import LiberoEnv, _get_suite, _select_task_ids, parse_camera_names
from libero.libero.envs import OffScreenRenderEnv
from robosuite import macros

IMAGE_FRESH = "image_fresh"  # becomes `observation.image_fresh` in LeRobot's preprocess_observation


class SparseRenderLiberoEnv(LiberoEnv):
    """Renders the cameras only on steps whose images the policy consumes.

    Observation k (after k actions) gets freshly rendered images when k % render_interval == 0; the other
    steps repeat the last images and carry `image_fresh = 0`. Every observation is read at the end of the
    control step with the same robosuite calls as `regenerate_obs_from_state`, which is how
    `predvla demos` (and LIBERO's own datasets) rendered the training data, so a fresh image equals the
    demonstrations' render of the same state.
    """

    def __init__(self, *args, render_interval: int = 4, **kwargs):
        super().__init__(*args, **kwargs)
        self.render_interval = render_interval
        self._steps_since_reset = 0
        self._images: dict[str, np.ndarray] | None = None
        self.observation_space.spaces[IMAGE_FRESH] = spaces.Box(0, 1, shape=(1,), dtype=np.uint8)

    def _ensure_env(self) -> None:
        if self._env is not None:
            return
        # Cameras are not robosuite observables here: rendering them at every physics step is what we avoid.
        self._env = OffScreenRenderEnv(
            bddl_file_name=self._task_bddl_file,
            camera_heights=self.observation_height,
            camera_widths=self.observation_width,
            control_freq=self.control_freq,
            hard_reset=self.hard_reset,
            use_camera_obs=False,
        )
        self._env.reset()

    def _render_cameras(self) -> dict[str, np.ndarray]:
        inner = self._env.env
        flip = -1 if macros.IMAGE_CONVENTION == "opencv" else 1  # as robosuite's camera sensor
        return {
            camera: inner.sim.render(
                camera_name=camera.removesuffix("_image"),
                width=self.observation_width,
                height=self.observation_height,
                depth=False,
            )[::flip]
            for camera in self.camera_name
        }

    def _format_raw_obs(self, raw_obs: dict) -> dict:
        # As regenerate_obs_from_state: positions recomputed for the end-of-step state (mj_step leaves them
        # one physics substep behind), then every observable re-read. Dynamics do not depend on this.
        self._env.env.sim.forward()
        raw_obs = dict(self._env.env._get_observations(force_update=True))
        fresh = self._images is None or self._steps_since_reset % self.render_interval == 0
        if fresh:
            self._images = self._render_cameras()
        raw_obs.update(self._images)
        observation = super()._format_raw_obs(raw_obs)
        observation[IMAGE_FRESH] = np.array([fresh], dtype=np.uint8)
        return observation

    def render(self) -> np.ndarray:
        """The first camera's latest images for lerobot-eval's videos, without rendering again."""
        if self._images is None:
            return super().render()
        return next(iter(self._images.values()))[::-1, ::-1]  # upright, as LiberoEnv.render

    def reset(self, seed=None, **kwargs):
        self._steps_since_reset, self._images = 0, None
        return super().reset(seed=seed, **kwargs)

    def step(self, action: np.ndarray):
        self._steps_since_reset += 1
        return super().step(action)


def create_envs(cfg, n_envs: int, env_cls) -> dict[str, dict[int, gym.vector.VectorEnv]]:
    """One vector env of `n_envs` rollouts per selected task, as `lerobot.envs.libero.create_libero_envs`."""
    camera_names = parse_camera_names(cfg.camera_name)
    kwargs = dict(cfg.gym_kwargs)
    task_ids = kwargs.pop("task_ids", None)
    out: dict[str, dict[int, gym.vector.VectorEnv]] = {}
    for suite_name in [s.strip() for s in str(cfg.task).split(",") if s.strip()]:
        suite = _get_suite(suite_name)
        out[suite_name] = {}
        for task_id in _select_task_ids(len(suite.tasks), task_ids):
            fns = [
                partial(
                    SparseRenderLiberoEnv,
                    task_suite=suite,
                    task_id=task_id,
                    task_suite_name=suite_name,
                    camera_name=camera_names,
                    init_states=cfg.init_states,
                    episode_length=cfg.episode_length,
                    episode_index=episode_index,
                    n_envs=n_envs,
                    control_mode=cfg.control_mode,
                    camera_name_mapping=cfg.camera_name_mapping,
                    **kwargs,
                )
                for episode_index in range(n_envs)
            ]
            if env_cls is gym.vector.SyncVectorEnv:
                out[suite_name][task_id] = env_cls(fns, autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
            else:
                out[suite_name][task_id] = env_cls(fns)
    return out
