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

LeRobot's own `--env.type=libero` works too: LeRobot 0.6.1 chooses env processors by policy config in
`make_env_pre_post_processors` (it special-cases X-VLA there) and offers plugins no hook, so the plugin wraps that
function the same way for its policies (lerobot_predvla/lerobot_integration.py). With the `libero` env type, the choice
follows the state the policy was trained on: a 9-dim state (joints + gripper, LIBERO's hdf5 demonstrations
through `predvla convert --hdf5-root`) gets `PredVLALiberoProcessorStep` instead of LeRobot's
`LiberoProcessorStep`; an 8-dim state (LeRobot's community LIBERO datasets through `predvla convert
--dataset-root`) gets LeRobot's own processor unchanged. Every other policy and env type gets LeRobot's
processors unchanged. The other two changes above are not available there (every step is
rendered, at 360 px unless `--env.observation_height/width=128`), so `predvla_libero` stays the default.

With `predvla_libero`, a fault in one sub-environment ends only that episode, as a failure (`predvla_libero`), and
`--env.fault_rate` injects sensor faults (`fault_injection`). The plugin also wraps LeRobot's `eval_policy_all`
(lerobot_predvla/lerobot_integration.py) so that `eval_info.json` gets a `predvla_faults` section (`fault_summary`):
faulted episodes with their reasons, non-finite actions received by the environments, observations the policy
masked, actions it replaced, and the injected faults.
"""

from dataclasses import dataclass

import torch
from lerobot.configs.types import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig, LiberoEnv, _make_vec_env_cls
from lerobot.processor import ObservationProcessorStep, PolicyProcessorPipeline, ProcessorStepRegistry
from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

from lerobot_predvla.columns import GRIPPER_DIM, JOINT_DIM
from lerobot_predvla.sims.libero.fault_injection import FaultInjectionStep
from lerobot_predvla.sims.libero.instructions import InstructionSource
from lerobot_predvla.sims.libero.object_shift import ShiftSpec
from lerobot_predvla.sims.libero.placed_resets import check_placement
from lerobot_predvla.sims.libero.protocol import EVAL_ENV_TYPE

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
            raise KeyError(f"'{OBS_ROBOT_STATE}' missing: PredVLA's proprio needs --env.obs_type=pixels_agent_pos.")
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


@EnvConfig.register_subclass(EVAL_ENV_TYPE)
@dataclass
class PredVLALiberoEnv(LiberoEnv):
    """LeRobot's LIBERO env config (`--env.task`, `--env.task_ids`, `--env.episode_length`, ...) for PredVLA.

    `--env.episode_length=600` is the paper's step cap (Section 4.4); left unset, LeRobot's per-suite caps
    apply (`lerobot_predvla.sims.libero.protocol.STEP_CAPS`: 280/280/300/520 for spatial/object/goal/10).

    Args:
        render_interval: Render the cameras every this many control steps (PredVLA's
            visual_refresh_interval, Table 1: 4); 1 renders every step.
        observation_height: Camera height in pixels (128, the size of LIBERO's demonstrations).
        observation_width: Camera width in pixels (128).
        fault_rate: Fraction in [0, 1] of camera frames and of proprio readings spoiled before the policy
            sees them (fault-injection evaluation, docs/reliability.md); 0 (default) injects nothing.
        fault_mode: "nan" (the frame's values become NaN) or "drop" (the frame is missing).
        fault_seed: Seed of the fault draws.
        oracle: Also observe the objects of interest's poses relative to the gripper
            (`observation.environment_state`), which a policy trained with the oracle front end (`predvla convert
            --oracle`, a diagnostic) reads instead of its cameras; False (default) for every other policy.
        object_shift_cm: Move the object to pick by this many cm from each official init state (`object_shift`);
            0 (default) moves nothing.
        target_shift_cm: Move the place target (libero_object's basket) by this many cm, opposite the object's
            direction; 0 (default) moves nothing.
        object_shift_pattern: Directions per episode: "ring" (episode k at 360 * k / object_shift_directions
            degrees) or "cross" (+x, -x, +y, -y in turn).
        object_shift_directions: Directions of the ring (8).
        shift_tolerance_cm: How far a shifted body may move while it settles before its episode is reported as
            unsettled (1 cm).
        placement_spread_cm: With `--env.init_states=false`: after each episode's randomised reset, before the
            settle steps, shift every movable object by an x, y offset drawn per axis from N(0, this many cm)
            truncated at twice that, exactly as `predvla demos --placement-spread-cm` does for a demonstration
            whose episode seed is the reset seed (`placed_resets`); 0 (default) shifts nothing. lerobot-eval's
            `--seed=s` seeds episode i of every task's reset with s + i (batch b of `--eval.batch_size` n resets
            its sub-environments with s + b * n ... s + b * n + n - 1, and each task starts again from s), so episode
            i of an evaluation with `--seed=3000` starts as the demonstration of episode seed 3000 + i would. Needs
            `--env.init_states=false` and a seed (lerobot-eval's default is 1000); cannot be combined with
            `--env.object_shift_cm` or `--env.target_shift_cm`. Every episode's offsets and whether the objects
            settled (within 1 cm) go to eval_info.json's `predvla_shifts` section.
        instruction_from_task: Run every selected task with this task's instruction (same suite), keeping the
            task's own scene, goal and success check (`instructions`); None (default): each task's own.
        instruction_shift: Run task k with task (k + instruction_shift) mod n's instruction (1: every task with the
            next one's, a paired evaluation of all tasks); 0 (default): each task's own. The instruction each task
            got is in eval_info.json (`predvla_instructions`).

    `--env.task` also takes LIBERO-PRO and LIBERO-plus variants, e.g. `libero_object_pro_temp_x0.1` or
    `libero_object_plus_language_3` (`variants`).
    """

    render_interval: int = 4
    observation_height: int = 128
    observation_width: int = 128
    fault_rate: float = 0.0
    fault_mode: str = "nan"
    fault_seed: int = 0
    oracle: bool = False
    object_shift_cm: float = 0.0
    target_shift_cm: float = 0.0
    object_shift_pattern: str = "ring"
    object_shift_directions: int = 8
    shift_tolerance_cm: float = 1.0
    placement_spread_cm: float = 0.0
    instruction_from_task: int | None = None
    instruction_shift: int = 0

    def __post_init__(self):
        super().__post_init__()
        if self.render_interval < 1:
            raise ValueError(f"--env.render_interval must be >= 1, got {self.render_interval}.")
        if self.obs_type != "pixels_agent_pos":
            raise ValueError(f"--env.obs_type must be 'pixels_agent_pos' for predvla_libero, got {self.obs_type!r}.")
        self.fault_injection()  # validates fault_rate and fault_mode
        check_placement(self.placement_spread_cm, self.init_states, self.shift().active)
        self.instructions()  # validates the instruction flags (their range per suite when the envs are made)
        self.shift().check_init_states(self.init_states)

    def shift(self) -> ShiftSpec:
        """The shift of `--env.object_shift_*` (validated here)."""
        return ShiftSpec(object_cm=self.object_shift_cm, target_cm=self.target_shift_cm,
                         pattern=self.object_shift_pattern, directions=self.object_shift_directions,
                         tolerance_cm=self.shift_tolerance_cm)

    def instructions(self) -> InstructionSource:
        """Which task's instruction each task is run with (`--env.instruction_from_task`, `--env.instruction_shift`)."""
        return InstructionSource(from_task=self.instruction_from_task, shift=self.instruction_shift)

    def fault_injection(self) -> FaultInjectionStep | None:
        if self.fault_rate == 0.0:
            return None
        return FaultInjectionStep(rate=self.fault_rate, mode=self.fault_mode, seed=self.fault_seed)

    @property
    def gym_kwargs(self) -> dict:
        return {**super().gym_kwargs, "render_interval": self.render_interval, "oracle": self.oracle,
                "shift": self.shift(), "placement_spread_cm": self.placement_spread_cm}

    def create_envs(self, n_envs: int, use_async_envs: bool = False):
        # The simulator (LIBERO, robosuite, MuJoCo), loaded once an env is built: registering the type loads none.
        from lerobot_predvla.sims.libero.predvla_libero import create_envs

        if self.task is None:
            raise ValueError("--env.task is required (a LIBERO suite, e.g. libero_object).")
        return create_envs(self, n_envs, _make_vec_env_cls(use_async_envs, n_envs))

    def get_env_processors(self):
        return libero_env_processors(self.fault_injection())


def libero_env_processors(
    fault_injection: FaultInjectionStep | None = None,
) -> tuple[PolicyProcessorPipeline, PolicyProcessorPipeline]:
    """Env pre/post-processors that turn LIBERO observations into what PredVLA consumes (then spoil some of
    them, with fault injection)."""
    steps = [PredVLALiberoProcessorStep(), *([fault_injection] if fault_injection is not None else [])]
    return PolicyProcessorPipeline(steps=steps), PolicyProcessorPipeline(steps=[])


def fault_summary(envs: dict, policy, env_preprocessor) -> dict:
    """The `predvla_faults` section of eval_info.json (see the module docstring)."""
    faulted, nonfinite_actions = [], 0
    for suite, tasks in envs.items():
        for vec_env in tasks.values():
            try:
                per_env, actions = vec_env.get_attr("faults"), vec_env.get_attr("nonfinite_actions")
            except AttributeError:  # not a predvla_libero env
                continue
            faulted += [{"suite": suite, **record} for records in per_env for record in records]
            nonfinite_actions += sum(actions)
    summary = {"faulted_episodes": sorted(faulted, key=lambda r: (r["suite"], r["task_id"], r["episode_ix"])),
               "nonfinite_actions": nonfinite_actions}
    guard = getattr(policy, "guard", None)
    if guard is not None:
        guard.reset()  # logs the last episode's report
        summary["policy"] = dict(guard.totals)
    injection = next((s for s in getattr(env_preprocessor, "steps", []) if isinstance(s, FaultInjectionStep)), None)
    if injection is not None:
        summary["injected"] = {**injection.get_config(), **injection.counts}
    return summary
