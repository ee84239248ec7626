"""Building LIBERO tasks: suites, environments without or with cameras, randomised resets.

Loading LIBERO (`_libero`, which every function here that needs it goes through) first sets MUJOCO_GL=egl unless it
is set (`use_headless_gl`), so rendering works headless on CPU. Importing this module sets nothing: a process that
never loads the simulator (and the commands it starts) keeps its environment as it was.
"""

import contextlib
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lerobot_predvla.columns import SIM_CAMERAS, SUITES
from lerobot_predvla.sims.libero.config_path import active_config

IMAGE_SIZE = 128
# robosuite's default initialization noise (std, rad, per arm joint): the official init states of the benchmark
# start the arm with it (their joint angles spread by 0.017-0.022 rad on libero_object), LIBERO's ControlEnv with none.
OFFICIAL_INIT_NOISE = 0.02
INSTALL_HINT = "LIBERO is not installed in this venv: run `make libero`"


def use_headless_gl() -> None:
    """MUJOCO_GL=egl unless it is set: call before MuJoCo's rendering loads (LIBERO, robosuite)."""
    os.environ.setdefault("MUJOCO_GL", "egl")


def check_libero_config() -> None:
    """Fail with the install hint (never prompting) unless LIBERO's config points at existing files."""
    config = active_config()
    if not config.is_file():
        raise RuntimeError(f"{config} missing ({INSTALL_HINT})")
    import yaml

    # ~/.libero is per user: another checkout's install may have pointed it at its own venv (config_path.py).
    bddl = Path(yaml.safe_load(config.read_text()).get("bddl_files", ""))
    if not bddl.is_dir():
        raise RuntimeError(f"{config}: `bddl_files` is {bddl}, which does not exist (a stale config from another "
                           f"environment?); run `make libero` in this checkout to rewrite it")


def _libero():
    """Import libero.libero, failing with the install hint (never prompting) if it is not set up."""
    check_libero_config()
    use_headless_gl()
    try:
        import libero.libero as libero_pkg
        from libero.libero import benchmark
    except ImportError as err:
        raise RuntimeError(f"{INSTALL_HINT} ({err})") from err
    return libero_pkg, benchmark


def libero_suite(name: str):
    """LIBERO's benchmark suite `name` (for example libero_object), built without the "[info] using task orders" line
    LIBERO prints each time it builds one (a sweep's planning and every task lookup build one)."""
    _, benchmark = _libero()
    suites = benchmark.get_benchmark_dict()
    if name not in suites:
        raise ValueError(f"unknown LIBERO suite {name!r}; expected one of {', '.join(sorted(suites))}")
    with contextlib.redirect_stdout(io.StringIO()):
        suite = suites[name]()
    if not getattr(suite, "tasks", None):  # as lerobot's own suite lookup checks
        raise ValueError(f"LIBERO suite {name!r} has no tasks")
    return suite


@dataclass(frozen=True)
class TaskSpec:
    suite: str
    task_id: int
    name: str
    language: str
    bddl_file: Path

    @property
    def bddl_relpath(self) -> str:
        """The BDDL path relative to the hf-libero package root, as stored in demonstrations."""
        return f"libero/libero/bddl_files/{self.suite}/{self.bddl_file.name}"


def task_spec(suite: str, task_id: int) -> TaskSpec:
    if suite not in SUITES:
        raise ValueError(f"unknown suite {suite!r}; expected one of {SUITES}")
    libero_pkg, _ = _libero()
    bench = libero_suite(suite)
    if not 0 <= task_id < bench.n_tasks:
        raise ValueError(f"task id {task_id} out of range for {suite} ({bench.n_tasks} tasks)")
    task = bench.get_task(task_id)
    bddl = Path(libero_pkg.get_libero_path("bddl_files")) / task.problem_folder / task.bddl_file
    return TaskSpec(suite, task_id, task.name, task.language, bddl)


def libero_instructions(suites: tuple[str, ...] = SUITES) -> tuple[str, ...]:
    """The language instructions of every task of `suites` from LIBERO's task list (no demonstration needed):
    40 for the four suites, the set the paper's language PCA is fitted on (Section 4.1)."""
    return tuple(task.language for suite in suites for task in libero_suite(suite).tasks)


def num_tasks(suite: str) -> int:
    return libero_suite(suite).n_tasks


def official_init_states(suite: str, task_id: int) -> np.ndarray:
    """The benchmark's official evaluation init states of one task (50 flattened simulator states)."""
    return libero_suite(suite).get_task_init_states(task_id)


def env_kwargs(spec: TaskSpec, render: bool, init_noise: float = 0.0) -> dict:
    """Keyword arguments of LIBERO's ControlEnv; `render` adds the two 128x128 cameras.

    `init_noise`: std (rad) of the Gaussian noise robosuite adds to the arm's initial joint angles at every reset.
    LIBERO's ControlEnv defaults to none; the benchmark's official init states carry robosuite's default,
    `OFFICIAL_INIT_NOISE`.
    """
    noise = {"initialization_noise": {"magnitude": init_noise, "type": "gaussian"}} if init_noise > 0 else {}
    return {
        **noise,
        "bddl_file_name": str(spec.bddl_file),
        "has_renderer": False,
        "has_offscreen_renderer": render,
        "use_camera_obs": render,
        "ignore_done": True,
        "camera_names": list(SIM_CAMERAS.values()),
        "camera_heights": IMAGE_SIZE,
        "camera_widths": IMAGE_SIZE,
        "camera_depths": False,
        "control_freq": 20,
    }


def make_env(spec: TaskSpec, render: bool = False, init_noise: float = 0.0):
    """A LIBERO ControlEnv (default OSC_POSE controller); physics only unless `render`."""
    _libero()
    from libero.libero.envs.env_wrapper import ControlEnv

    return ControlEnv(**env_kwargs(spec, render, init_noise))


def random_reset(env, seed: int) -> dict:
    """Reset with object placements drawn from the BDDL regions (not the official init states), and the arm's
    initial joint noise if the env has any (`make_env(init_noise=...)`)."""
    np.random.seed(seed)  # robosuite's placement samplers and joint noise draw from numpy's global generator
    return env.reset()


def fixture_poses(env) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """World pose of each fixture body: resets jitter them in the model, outside the sim state."""
    inner, model = env.env, env.sim.model
    poses = {}
    for fixture in inner.fixtures_dict.values():
        body = model.body_name2id(fixture.root_body)
        poses[fixture.root_body] = (model.body_pos[body].copy(), model.body_quat[body].copy())
    return poses


def set_fixture_poses(env, poses: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    model = env.sim.model
    for name, (pos, quat) in poses.items():
        body = model.body_name2id(name)
        model.body_pos[body] = pos
        model.body_quat[body] = quat
