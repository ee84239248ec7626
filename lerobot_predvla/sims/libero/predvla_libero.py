"""The `predvla_libero` gym env: LeRobot's LiberoEnv with end-of-step observations and sparse rendering.

Every sub-environment of a process renders through one `SharedRenderer` (one GL context, one MuJoCo render
context per set of rendering assets) instead of robosuite's own context per environment, rebuilt at each
hard reset: on CPU (llvmpipe) each of those held its textures, meshes, shadow map and framebuffers in
process memory (docs/speed.md, "Evaluation memory"). The images are the same, bit for bit
(tests/test_eval_memory.py).

A fault in one sub-environment (an exception from MuJoCo or robosuite, a non-finite simulator state, an
unstable-simulation warning or a non-finite action) ends that episode as a failure with its reason; the
other sub-environments and the run go on. Faults are kept in `faults` and listed in `eval_info.json`.

lerobot-eval steps a batch until its last episode ends. A sub-environment whose episode has ended replays its last
transition instead of simulating (`FreezeFinishedEpisode`, LeRobot's `FreezeAfterEpisodeEnd`, which LeRobot itself
applies to its asynchronous environments only): without it, Gymnasium's autoreset starts an episode there that
lerobot-eval discards, and it is simulated and rendered to the end of the batch. The episodes lerobot-eval keeps are
the same, bit for bit: a row's actions do not depend on what the other rows see
(tests/test_policy.py::test_a_rows_actions_do_not_depend_on_what_the_other_rows_see).
"""

import atexit
import logging
import queue
import threading
import zlib
from concurrent.futures import Future
from functools import partial

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from lerobot_predvla.frontend.oracle import POSE_DIM
from lerobot_predvla.sims.libero.env import check_libero_config, libero_suite, use_headless_gl
from lerobot_predvla.sims.libero.object_shift import ShiftedResets, ShiftSpec
from lerobot_predvla.sims.libero.oracle import object_poses, objects_of_interest
from lerobot_predvla.sims.libero.placed_resets import PlacedResets, check_placement
from lerobot_predvla.sims.libero.variants import variant_suite

check_libero_config()  # before LIBERO reads its config: a stale one otherwise fails deep inside a reset
use_headless_gl()  # before robosuite chooses its GL context

from lerobot.envs.libero import LiberoEnv, _select_task_ids, parse_camera_names  # noqa: E402
from lerobot.envs.utils import NEW_ROLLOUT_OPTION, FreezeAfterEpisodeEnd  # noqa: E402
from libero.libero.envs.bddl_utils import robosuite_parse_problem  # noqa: E402
from libero.libero.envs.env_wrapper import ControlEnv  # noqa: E402
from robosuite import macros  # noqa: E402
from robosuite.utils.binding_utils import GLContext  # noqa: E402  (robosuite's choice for MUJOCO_GL)

IMAGE_FRESH = "image_fresh"  # becomes `observation.image_fresh` in LeRobot's preprocess_observation
ENVIRONMENT_STATE = "environment_state"  # becomes `observation.environment_state` (the oracle's object poses)
UNSTABLE = mujoco.mjtWarning.mjWARN_BADQACC  # MuJoCo's "NaN, Inf or huge value in QACC": it resets the state
# What `mujoco.MjrContext` uploads from a model (textures, meshes, height fields, skins, flexes) besides the
# visual settings: two models equal in these render alike through one context.
RENDER_ASSET_PREFIXES = ("tex_", "mesh_", "hfield_", "skin_", "flex_")


def render_assets_key(model: mujoco.MjModel) -> str:
    """A digest of everything a MuJoCo render context takes from `model` (its assets and visual settings).

    The sub-environments of one task load the same scene, and robosuite's hard reset reloads it at every
    episode: the key stays the same, so the shared render context is kept. Computed once per model (each reset):
    CRC-32 per array, 3-4x faster than a cryptographic hash over a LIBERO scene's ~200 MB of assets.
    """
    parts = [repr((model.vis, model.stat))]
    for name in sorted(n for n in dir(model) if n.startswith(RENDER_ASSET_PREFIXES)):
        value = getattr(model, name)
        if isinstance(value, np.ndarray):
            parts.append(f"{name}{value.shape}{value.dtype}:{zlib.crc32(np.ascontiguousarray(value).view(np.uint8))}")
    return "\n".join(parts)


class GLThread:
    """One daemon thread that runs every GL call of the shared renderer.

    A GL context is current per thread, and robosuite relies on the calling thread's current context: its
    renderers draw with whichever context was made current last (their own, at creation) and free their MuJoCo
    context (`MjRenderContext.__del__`) without making their GL context current, deleting textures and buffers by
    number in whichever context is. On its own thread the shared context is never the main thread's current
    one, so neither can touch the other's (tests/test_eval_memory.py). A daemon thread still runs during `atexit`
    handlers, where the renderer is closed.
    """

    def __init__(self):
        self._calls: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._start_lock = threading.Lock()

    def call(self, function, *args):
        """`function(*args)` on the GL thread; its result, or its exception raised here."""
        with self._start_lock:
            if self._thread is None or not self._thread.is_alive():  # not started, or a forked child's
                self._thread = threading.Thread(target=self._serve, name="predvla-gl", daemon=True)
                self._thread.start()
        result = Future()
        self._calls.put((function, args, result))
        return result.result()

    def _serve(self) -> None:
        while True:
            function, args, result = self._calls.get()
            try:
                result.set_result(function(*args))
            except BaseException as error:  # handed to the caller, which raises it
                result.set_exception(error)


class SharedRenderer:
    """One GL context and one MuJoCo render context for every simulator of the process.

    Draws exactly as robosuite's `MjRenderContextOffscreen.render` + `read_pixels` (same scene size, camera,
    visual/collision geom groups, offscreen buffer and font scale), for any model whose `render_assets_key`
    matches the context's; a model with other assets (the next task) replaces the context. Every GL call runs
    on one `GLThread`, where this context is the only one ever made current.
    """

    MAX_GEOMS = 1000  # robosuite's MjvScene size

    def __init__(self):
        self._thread = GLThread()
        self._gl = None
        self._key: str | None = None
        self._context: mujoco.MjrContext | None = None
        self._scene: mujoco.MjvScene | None = None
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._option = mujoco.MjvOption()
        self._perturb = mujoco.MjvPerturb()
        self._perturb.active, self._perturb.select, self._perturb.skinselect = 0, 0, -1
        self.contexts_built = 0  # render contexts made so far (tests check sub-environments share one)

    def _bind(self, model: mujoco.MjModel, key: str, width: int, height: int) -> None:
        if self._gl is None:  # robosuite's context class for MUJOCO_GL (it ignores the size arguments)
            self._gl = GLContext(max_width=width, max_height=height, device_id=-1)
            # robosuite registers the display's termination with the first context; atexit runs last-first, so
            # this frees the contexts before it (else robosuite's __del__ prints a traceback at exit).
            atexit.register(self.close)
        self._gl.make_current()  # at every call: a forked child's GL thread is a new one (GLThread.call)
        if key == self._key and width <= self._context.offWidth and height <= self._context.offHeight:
            return
        if self._context is not None:
            self._context.free()
        # As robosuite's update_offscreen_size: the model's offscreen size, grown to the image if smaller.
        model.vis.global_.offwidth = max(width, model.vis.global_.offwidth)
        model.vis.global_.offheight = max(height, model.vis.global_.offheight)
        self._context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._context)
        self._scene = mujoco.MjvScene(model, maxgeom=self.MAX_GEOMS)
        self._key = key
        self.contexts_built += 1

    def render(self, env, key: str, camera: str, width: int, height: int) -> np.ndarray:
        """RGB image (height, width, 3) of robosuite env `env`'s camera `camera`, bottom row first (OpenGL);
        `key` is `render_assets_key` of its model."""
        return self._thread.call(self._render, env, key, camera, width, height)

    def _render(self, env, key: str, camera: str, width: int, height: int) -> np.ndarray:
        model, data = env.sim.model._model, env.sim.data._data
        self._bind(model, key, width, height)
        self._camera.fixedcamid = env.sim.model.camera_name2id(camera)
        self._option.geomgroup[0] = 1 if env.render_collision_mesh else 0
        self._option.geomgroup[1] = 1 if env.render_visual_mesh else 0
        mujoco.mjv_updateScene(model, data, self._option, self._perturb, self._camera,
                               mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        viewport = mujoco.MjrRect(0, 0, width, height)
        mujoco.mjr_render(viewport, self._scene, self._context)
        image = np.empty((height, width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(image, None, viewport, self._context)
        return image

    def close(self) -> None:
        """Free the render context and the GL context (at exit, or to start again)."""
        self._thread.call(self._close)

    def _close(self) -> None:
        if self._gl is not None:
            if self._context is not None:
                self._context.free()
            self._gl.free()
        self._gl, self._context, self._scene, self._key = None, None, None, None


RENDERER = SharedRenderer()


class PlacingControlEnv(ControlEnv):
    """LIBERO's ControlEnv whose `reset` ends with `after_reset(self)`: between the simulator's reset and whatever
    follows it (in `LiberoEnv.reset`, the settle steps), as `predvla demos` shifts its placements."""

    def __init__(self, *args, after_reset=None, **kwargs):
        self.after_reset = after_reset
        super().__init__(*args, **kwargs)

    def reset(self):
        observation = super().reset()
        if self.after_reset is None:
            return observation
        self.after_reset(self)
        return self.env._get_observations(force_update=True)


class SparseRenderLiberoEnv(LiberoEnv):
    """Renders the cameras only on steps whose images the policy consumes.

    Observation k (after k actions) gets freshly rendered images when k % render_interval == 0; the other
    steps repeat the last images and carry `image_fresh = 0`. Every observation is read at the end of the
    control step with the same robosuite calls as `regenerate_obs_from_state`, which is how
    `predvla demos` (and LIBERO's own datasets) rendered the training data, so a fresh image equals the
    demonstrations' render of the same state.

    With `oracle`, every observation also carries the objects of interest's poses relative to the gripper
    (`environment_state`, `libero.oracle.object_poses`): the inputs of the oracle front end, a diagnostic.

    With an active `shift` (`object_shift.ShiftSpec`), each episode starts from its official init state with the object
    to pick (and/or its place target) moved; with `placement_spread_cm` > 0 (`placed_resets`), from a randomised reset
    with every movable object shifted as `predvla demos --placement-spread-cm` shifts them. Either way `shift_records`
    keeps one record per counted episode.

    With `instruction_task`, the policy reads that task's instruction (`task_description`, what lerobot-eval puts into
    the observation's `task`) while the scene, goal and success check stay this task's (`instructions`);
    `instruction_record` says which instruction was used.
    """

    def __init__(self, *args, render_interval: int = 4, oracle: bool = False, shift: ShiftSpec | None = None,
                 placement_spread_cm: float = 0.0, instruction_task: int | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        own_instruction = self.task_description
        if instruction_task is not None:
            self.task_description = kwargs["task_suite"].get_task(instruction_task).language
        self.instruction_record = {
            "task_id": self.task_id, "task": self.task, "own_instruction": own_instruction,
            "instruction": self.task_description,
            "instruction_from_task": self.task_id if instruction_task is None else instruction_task,
        }
        shifting = shift is not None and shift.active
        check_placement(placement_spread_cm, self.init_states, shifting)
        if shifting:
            shift.check_init_states(self.init_states)
        self.shifts = ShiftedResets(shift) if shifting else None
        self.placements = PlacedResets(placement_spread_cm) if placement_spread_cm > 0 else None
        self.shift_records: list[dict] = []
        self._official_states = None if self.shifts is None else np.array(self._init_states, copy=True)
        self.render_interval = render_interval
        self.oracle_objects = objects_of_interest(robosuite_parse_problem(self._task_bddl_file)) if oracle else []
        if oracle:
            self.observation_space.spaces[ENVIRONMENT_STATE] = spaces.Box(
                -np.inf, np.inf, shape=(POSE_DIM * len(self.oracle_objects),), dtype=np.float32
            )
        self._steps_since_reset = 0
        self._images: dict[str, np.ndarray] | None = None
        self._render_key: str | None = None  # render_assets_key of the current model (robosuite rebuilds it)
        self.observation_space.spaces[IMAGE_FRESH] = spaces.Box(0, 1, shape=(1,), dtype=np.uint8)
        self.faults: list[dict] = []  # one record per faulted episode
        self.nonfinite_actions = 0  # actions received with a NaN or infinite component
        self._rollouts = 0  # lerobot-eval rollouts started (each an episode of this sub-environment)
        self._counted = False  # False in the extra episodes of Gymnasium's autoreset, which lerobot-eval discards
        self._last_observation: dict | None = None

    def _ensure_env(self) -> None:
        if self._env is not None:
            return
        # Cameras are not robosuite observables here: rendering them at every physics step is what we avoid.
        # No robosuite renderer either (LIBERO's OffScreenRenderEnv forces one): `RENDERER` draws the cameras.
        self._env = PlacingControlEnv(
            after_reset=None if self.placements is None else self.placements.place,
            bddl_file_name=self._task_bddl_file,
            camera_heights=self.observation_height,
            camera_widths=self.observation_width,
            control_freq=self.control_freq,
            hard_reset=self.hard_reset,
            use_camera_obs=False,
            has_offscreen_renderer=False,
        )
        self._env.reset()

    def _render_cameras(self) -> dict[str, np.ndarray]:
        inner = self._env.env
        if self._render_key is None:  # first render since the last reset, which may have reloaded the model
            self._render_key = render_assets_key(inner.sim.model._model)
        flip = -1 if macros.IMAGE_CONVENTION == "opencv" else 1  # as robosuite's camera sensor
        return {
            camera: RENDERER.render(
                inner, self._render_key, camera.removesuffix("_image"), self.observation_width, self.observation_height
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
        if self.oracle_objects:
            observation[ENVIRONMENT_STATE] = object_poses(raw_obs, self.oracle_objects)
        return observation

    def render(self) -> np.ndarray:
        """The first camera's latest images for lerobot-eval's videos, without rendering again."""
        if self._images is None:
            return super().render()
        return next(iter(self._images.values()))[::-1, ::-1]  # upright, as LiberoEnv.render

    def reset(self, seed=None, options=None, **kwargs):
        self._counted = bool((options or {}).get(NEW_ROLLOUT_OPTION))
        self._rollouts += self._counted
        if self._counted:  # Gymnasium's autoresets (extra episodes lerobot-eval discards) moved init_state_id on
            self.init_state_id = (self._rollouts - 1) * self._reset_stride + self.episode_index
        self._steps_since_reset, self._images, self._render_key = 0, None, None
        episode = self.init_state_id  # LiberoEnv.reset starts from official init state episode % 50, then moves on
        if self.placements is not None:  # lerobot-eval's rollouts only: Gymnasium's autoresets carry no seed
            if self._counted and seed is None:
                raise ValueError("--env.placement_spread_cm shifts each episode's objects by its reset seed: run "
                                 "lerobot-eval with --seed.")
            self.placements.seed = seed if self._counted else None
        try:
            self._shift_start(episode)
            observation, info = super().reset(seed=seed, **kwargs)
        except Exception as err:  # noqa: BLE001  (a simulator left broken by a fault: rebuild it once)
            logging.warning("predvla_libero: reset failed (%s: %s); rebuilding the simulator.", type(err).__name__, err)
            self._drop_simulator()
            self.init_state_id = episode
            self._shift_start(episode)
            observation, info = super().reset(seed=seed, **kwargs)
        record = self._shift_record(episode)
        if record is not None:
            info = {**info, "shift_settled": record["settled"]}
            if self._counted:
                self.shift_records.append(record)
                if not record["settled"]:
                    logging.warning("predvla_libero: shifted objects did not settle where they were put: %s", record)
        self._last_observation = observation
        return observation, info

    def _shift_record(self, episode: int) -> dict | None:
        """After the reset's settle steps: this episode's shifted objects (`--env.object_shift_cm` or, on lerobot-eval's
        rollouts, `--env.placement_spread_cm`) and whether they settled; None when nothing was shifted."""
        where = {"episode_ix": episode, "task": self.task, "task_id": self.task_id}
        if self.shifts is not None:
            return {**where, "init_state": episode % len(self._official_states), **self.shifts.settle(self._env)}
        if self.placements is not None and self._counted:
            return {**where, **self.placements.settle(self._env)}
        return None

    def _shift_start(self, episode: int) -> None:
        """Put this episode's shifted state where `LiberoEnv.reset` takes its official init state from."""
        if self.shifts is None:
            return
        self._ensure_env()
        index = episode % len(self._official_states)
        self._init_states = self._official_states.copy()
        self._init_states[index] = self.shifts.shifted(self._env, self._official_states[index], episode)

    def step(self, action: np.ndarray):
        self._steps_since_reset += 1
        if not np.isfinite(action).all():
            self.nonfinite_actions += 1
            return self._fault(f"non-finite action {np.asarray(action).tolist()}")
        try:
            self._ensure_env()
            warnings_before = self._env.env.sim.data._data.warning[UNSTABLE].number
            observation, reward, terminated, truncated, info = super().step(action)
            data = self._env.env.sim.data
            for name in ("qpos", "qvel"):
                if not np.isfinite(getattr(data, name)).all():
                    return self._fault(f"non-finite simulator state ({name})")
            if data._data.warning[UNSTABLE].number > warnings_before:
                return self._fault("MuJoCo reported an unstable simulation (NaN, Inf or huge value in QACC)")
        except Exception as err:  # noqa: BLE001  (MuJoCo and robosuite raise many types; none may end the run)
            return self._fault(f"{type(err).__name__}: {err}")
        self._last_observation = observation
        return observation, reward, terminated, truncated, info

    def _drop_simulator(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001  (a broken simulator may fail to close; it is dropped anyway)
            self._env = None

    def _fault(self, reason: str):
        """End this episode as a failure: record the reason, drop the simulator (rebuilt at the next reset)
        and return the last good observation with `terminated=True` and `is_success=False`."""
        record = {
            "episode_ix": max(self._rollouts - 1, 0) * self._reset_stride + self.episode_index,
            "task": self.task,
            "task_id": self.task_id,
            "step": self._steps_since_reset,
            "reason": reason,
        }
        if self._counted:
            self.faults.append(record)
            logging.warning("predvla_libero: episode faulted and ended as a failure: %s", record)
        self._drop_simulator()
        info = {"task": self.task, "task_id": self.task_id, "done": True, "is_success": False, "fault": reason}
        return self._last_observation, 0.0, True, False, info


class FreezeFinishedEpisode(FreezeAfterEpisodeEnd):
    """LeRobot's `FreezeAfterEpisodeEnd` (once an episode has ended, further steps and Gymnasium's autoreset replay
    its last transition; a reset with `NEW_ROLLOUT_OPTION` starts the next rollout) whose replays carry
    `image_fresh = 0`: a finished sub-environment never makes the front end encode the batch's frames again. The
    sub-environment itself is `unwrapped`."""

    def step(self, action):
        transition = super().step(action)
        if self._frozen is not None and self._frozen[0][IMAGE_FRESH][0]:
            observation = {**self._frozen[0], IMAGE_FRESH: np.zeros(1, dtype=np.uint8)}
            self._frozen = (observation, *self._frozen[1:])
        return transition


def frozen_env(**kwargs) -> FreezeFinishedEpisode:
    """A `SparseRenderLiberoEnv(**kwargs)` that freezes once its episode ends."""
    return FreezeFinishedEpisode(SparseRenderLiberoEnv(**kwargs))


def create_envs(cfg, n_envs: int, env_cls) -> dict[str, dict[int, gym.vector.VectorEnv]]:
    """One vector env of `n_envs` rollouts per selected task, as `lerobot.envs.libero.create_libero_envs`, each
    sub-environment frozen once its episode ends (`FreezeFinishedEpisode`)."""
    camera_names = parse_camera_names(cfg.camera_name)
    kwargs = dict(cfg.gym_kwargs)
    task_ids = kwargs.pop("task_ids", None)
    instructions = cfg.instructions()
    out: dict[str, dict[int, gym.vector.VectorEnv]] = {}
    for suite_name in [s.strip() for s in str(cfg.task).split(",") if s.strip()]:
        # A LIBERO-PRO or LIBERO-plus variant (`variants`) runs with its base suite's step cap.
        suite, base_name = variant_suite(suite_name) or (libero_suite(suite_name), suite_name)
        out[suite_name] = {}
        for task_id in _select_task_ids(len(suite.tasks), task_ids):
            instruction_task = instructions.task_for(task_id, len(suite.tasks), suite_name)  # validated before any env
            fns = [
                partial(
                    frozen_env,
                    task_suite=suite,
                    task_id=task_id,
                    task_suite_name=base_name,
                    camera_name=camera_names,
                    init_states=cfg.init_states,
                    episode_length=cfg.episode_length,
                    episode_index=episode_index,
                    n_envs=n_envs,
                    control_mode=cfg.control_mode,
                    camera_name_mapping=cfg.camera_name_mapping,
                    instruction_task=instruction_task if instructions.active else None,
                    **kwargs,
                )
                for episode_index in range(n_envs)
            ]
            if env_cls is gym.vector.SyncVectorEnv:
                out[suite_name][task_id] = env_cls(fns, autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
            else:
                out[suite_name][task_id] = env_cls(fns)
    return out
