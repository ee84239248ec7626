"""Evaluation memory: `predvla_libero` sub-environments render through one shared GL/MuJoCo render context.

robosuite's own renderer gives every environment a GL context and a render context (textures, meshes, shadow map
and framebuffers, all in process memory on a CPU) and rebuilds them at every hard reset; docs/speed.md
("Evaluation memory") measures what that cost. These tests check that no sub-environment holds one, that the
shared context draws the same pixels as robosuite's, and that a further environment costs far less memory.
"""

import numpy as np
import pytest

from lerobot_predvla.columns import SIM_CAMERAS
from lerobot_predvla.sims.libero.env import use_headless_gl

pytestmark = pytest.mark.simulator
use_headless_gl()  # before the tests below load the simulator

SUITE = "libero_object"


def rss_gb() -> float:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:")) * 1024 / 1e9


def test_sub_environments_share_one_render_context_with_robosuites_pixels():
    from libero.libero.envs import OffScreenRenderEnv
    from robosuite import macros

    from lerobot_predvla.sims.libero import predvla_libero
    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    cfg = PredVLALiberoEnv(task=SUITE, task_ids=[0])
    venv = cfg.create_envs(n_envs=2)[SUITE][0]
    built = predvla_libero.RENDERER.contexts_built
    obs, _info = venv.reset(seed=[0, 1])
    obs, _info = venv.reset(seed=[0, 1])  # a second hard reset: new models, same rendering assets
    assert predvla_libero.RENDERER.contexts_built - built <= 1  # at most one: none if a previous test left it
    for sub_env in venv.envs:
        assert sub_env.unwrapped._env.env.sim._render_context_offscreen is None  # no robosuite renderer per environment
    # robosuite's own renderer (LIBERO's OffScreenRenderEnv, its context made current) on the same states.
    reference = OffScreenRenderEnv(bddl_file_name=venv.envs[0].unwrapped._task_bddl_file, camera_heights=128,
                                   camera_widths=128, use_camera_obs=False)
    reference.reset()
    flip = -1 if macros.IMAGE_CONVENTION == "opencv" else 1
    for i, sub_env in enumerate(venv.envs):
        reference.set_init_state(sub_env.unwrapped._env.get_sim_state())
        sim = reference.env.sim
        for camera, key in zip(SIM_CAMERAS.values(), ("image", "image2"), strict=True):
            sim._render_context_offscreen.gl_ctx.make_current()
            expected = sim.render(camera_name=camera, width=128, height=128)[::flip]
            assert expected.std() > 0  # a real scene, not a blank buffer
            np.testing.assert_array_equal(obs["pixels"][key][i], expected)
    reference.close()
    venv.close()


def test_a_robosuite_renderer_freed_later_leaves_the_shared_context_intact():
    """robosuite frees a renderer's MuJoCo context without making its own GL context current: it deletes
    textures and buffers by number in whichever context is current. The shared context is current only on its own
    thread, so a robosuite environment collected after it drew (an earlier test's, in a test runner) changes
    nothing it draws, and robosuite's renderer still draws with its own context (it never makes it current)."""
    import gc

    from libero.libero.envs import OffScreenRenderEnv
    from robosuite import macros

    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv

    venv = PredVLALiberoEnv(task=SUITE, task_ids=[0]).create_envs(n_envs=1)[SUITE][0]
    venv.reset(seed=[0])
    sub_env = venv.envs[0].unwrapped
    before = sub_env._render_cameras()
    reference = OffScreenRenderEnv(bddl_file_name=sub_env._task_bddl_file, camera_heights=128, camera_widths=128)
    reference.reset()
    assert all(np.array_equal(image, before[k]) for k, image in sub_env._render_cameras().items())
    reference.set_init_state(sub_env._env.get_sim_state())  # robosuite's renderer, its context not made current
    flip = -1 if macros.IMAGE_CONVENTION == "opencv" else 1
    expected = reference.env.sim.render(camera_name="agentview", width=128, height=128)[::flip]
    np.testing.assert_array_equal(expected, before["agentview_image"])
    reference.close()
    del reference
    gc.collect()  # robosuite's MjRenderContext.__del__ frees its MuJoCo context here
    after = sub_env._render_cameras()
    for camera, image in before.items():
        assert image.std() > 0
        np.testing.assert_array_equal(after[camera], image, err_msg=camera)
    venv.close()


def test_a_further_environment_costs_a_fraction_of_robosuites_renderer(tmp_path):
    """The per-environment cost: the peak resident memory of a fresh process with two reset and stepped environments,
    against one with five (benchmarks/bench_eval_memory.py's child, as docs/speed.md's table measures it). Two, not
    one: a process with several environments holds a further ~0.45 GB once (1 -> 4 environments: 0.41 GB each,
    1 -> 10: 0.31), so the slope is taken where both counts have it.

    With a robosuite renderer per environment each one added ~0.75 GB; without, about 0.3 GB, of which its MuJoCo
    model is 0.25 GB (docs/speed.md, "Evaluation memory"). Fresh processes: in the test runner's own process what
    earlier tests left in the allocator moves resident memory by hundreds of MB either way. The bound sits halfway
    between the two costs: on a machine whose memory other processes hold it measured 0.43 GB, idle 0.3."""
    import sys

    from benchmarks.bench_eval_memory import peak_rss_gb

    peak = {}
    for n_envs in (2, 5):
        command = [sys.executable, "-m", "benchmarks.bench_eval_memory", "--environments-only", str(n_envs),
                   "--steps", "5"]
        peak[n_envs] = peak_rss_gb(command, tmp_path / f"envs_{n_envs}.log")
    assert (peak[5] - peak[2]) / 3 < 0.55, peak


def test_the_shared_render_context_is_freed_before_exit_without_a_traceback():
    """robosuite terminates the EGL display at exit; the shared contexts are freed before it, so a process that
    rendered ends without robosuite's "Exception ignored in ... __del__" traceback."""
    import subprocess
    import sys

    # The first atexit handler runs last: it drops the renderer after every other one ran, as a test runner's
    # teardown does (a plain script may never collect module globals at exit).
    code = ("import atexit, gc, sys\n"
            "atexit.register(lambda: (setattr(sys.modules['lerobot_predvla.sims.libero.predvla_libero'], 'RENDERER',"
            " None), gc.collect()))\n"
            "from lerobot_predvla.sims.libero import predvla_libero\n"
            "from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv\n"
            "venv = PredVLALiberoEnv(task='libero_object', task_ids=[0]).create_envs(n_envs=1)['libero_object'][0]\n"
            "venv.reset(seed=[0])\n"
            "assert predvla_libero.RENDERER.contexts_built >= 1\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "Exception ignored" not in out.stderr and "EGLError" not in out.stderr, out.stderr[-2000:]
