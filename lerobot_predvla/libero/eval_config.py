"""`--env.type=predvla_libero`: LeRobot's LIBERO evaluation with the observations PredVLA consumes.

LeRobot's `libero` env type turns the robot state into an 8-dim end-effector vector and drops the joint
positions, but PredVLA's proprioception is joints 7 + gripper 2 (Table 1), as in LIBERO's demonstrations.
It also renders both cameras at every step although PredVLA takes a fresh image every
`visual_refresh_interval` steps. This env type keeps LeRobot's tasks, official init states, step caps and
vectorisation, and changes three things:

- proprioception: `observation.state` = `robot0_joint_pos` (7) + `robot0_gripper_qpos` (2);
- observations are read at the end of each control step (as `predvla demos` records them by replaying
  saved states), not at the first physics substep;
- cameras are rendered only every `render_interval` steps at 128 px (the demonstrations' size); the
  steps in between repeat the last images and say so in `observation.image_fresh`.
"""

from dataclasses import dataclass

import torch
from lerobot.configs.types import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig, LiberoEnv, _make_vec_env_cls
from lerobot.processor import ObservationProcessorStep, PolicyProcessorPipeline, ProcessorStepRegistry
from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

JOINT_DIM, GRIPPER_DIM = 7, 2
OBS_ROBOT_STATE = "observation.robot_state"


@ProcessorStepRegistry.register("predvla_libero_processor")
@dataclass
class PredVLALiberoProcessorStep(ObservationProcessorStep):
    """Rotate images by 180 degrees (LeRobot's LIBERO convention) and build joints + gripper proprio."""

    def observation(self, observation: dict) -> dict:
        out = {k: v for k, v in observation.items() if k != OBS_ROBOT_STATE}
        for key in [k for k in out if k.startswith(f"{OBS_IMAGES}.")]:
            out[key] = torch.flip(out[key], dims=[2, 3])
        robot_state = observation.get(OBS_ROBOT_STATE)
        if robot_state is None:
            raise KeyError(f"'{OBS_ROBOT_STATE}' missing: predvla_libero needs --env.obs_type=pixels_agent_pos.")
        state = torch.cat([robot_state["joints"]["pos"], robot_state["gripper"]["qpos"]], dim=-1).float()
        out[OBS_STATE] = state[None] if state.dim() == 1 else state
        return out

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        observation = {
            k: v for k, v in features.get(PipelineFeatureType.OBSERVATION, {}).items() if v.type != FeatureType.STATE
        }
        observation[OBS_STATE] = PolicyFeature(type=FeatureType.STATE, shape=(JOINT_DIM + GRIPPER_DIM,))
        return {**features, PipelineFeatureType.OBSERVATION: observation}


@EnvConfig.register_subclass("predvla_libero")
@dataclass
class PredVLALiberoEnv(LiberoEnv):
    """LeRobot's LIBERO env config (`--env.task`, `--env.task_ids`, `--env.episode_length`, ...) for PredVLA.

    `--env.episode_length=600` is the paper's step cap (Section 4.4); left unset, LeRobot's per-suite caps
    apply (220/280/300/520 for spatial/object/goal/10).

    Args:
        render_interval: Render the cameras every this many control steps (PredVLA's
            visual_refresh_interval, Table 1: 4); 1 renders every step.
        observation_height: Camera height in pixels (128, the size of LIBERO's demonstrations).
        observation_width: Camera width in pixels (128).
    """

    render_interval: int = 4
    observation_height: int = 128
    observation_width: int = 128

    def __post_init__(self):
        super().__post_init__()
        if self.render_interval < 1:
            raise ValueError(f"--env.render_interval must be >= 1, got {self.render_interval}.")
        if self.obs_type != "pixels_agent_pos":
            raise ValueError(f"--env.obs_type must be 'pixels_agent_pos' for predvla_libero, got {self.obs_type!r}.")

    @property
    def gym_kwargs(self) -> dict:
        return {**super().gym_kwargs, "render_interval": self.render_interval}

    def create_envs(self, n_envs: int, use_async_envs: bool = False):
        from .eval_env import create_envs

        if self.task is None:
            raise ValueError("--env.task is required (a LIBERO suite, e.g. libero_object).")
        return create_envs(self, n_envs, _make_vec_env_cls(use_async_envs, n_envs))

    def get_env_processors(self):
        return PolicyProcessorPipeline(steps=[PredVLALiberoProcessorStep()]), PolicyProcessorPipeline(steps=[])
