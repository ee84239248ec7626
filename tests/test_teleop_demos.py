"""Demonstration styles and shifted placements in the simulator (`predvla demos --style`, `--placement-spread-cm`).

Needs the simulator (`make libero`, which `make test` runs first); without it the test fails.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.simulator

SUITE, TASK_ID = "libero_object", 0
CAP = 280  # libero_object's step cap (protocol.STEP_CAPS)
# The Table 2 dataset's demonstrations regenerated: digests of each one's actions and states, and where they were made.
FINGERPRINT = Path(__file__).parents[1] / "results/libero_object_reading_machines/regeneration/fingerprint.json"


@pytest.fixture(scope="module")
def env_mod():
    try:
        from lerobot_predvla.sims.libero import env

        env.task_spec(SUITE, TASK_ID)
    except (RuntimeError, ImportError) as err:
        pytest.fail(f"LIBERO is not installed: run `make libero` ({err})")
    return env


# The first demonstration of task 0, scripted, and its digests, in a process of its own (its OpenBLAS kernels are
# chosen when numpy loads).
REGENERATE = f"""
import hashlib
from lerobot_predvla.sims.libero import env
from lerobot_predvla.sims.libero.record import episode_seed
from lerobot_predvla.sims.libero.rollout import run_episode
from lerobot_predvla.utils.versions import openblas_coretype
e = env.make_env(env.task_spec({SUITE!r}, {TASK_ID}), init_noise=env.OFFICIAL_INIT_NOISE)
ep = run_episode(e, episode_seed(0, {TASK_ID}, 0), {CAP}, "wrist_centre")
print(openblas_coretype(), *(hashlib.sha256(a.tobytes()).hexdigest()[:16] for a in (ep.actions, ep.states)))
"""
# What OpenBLAS needs of the processor to run each kernel set that committed datasets were made under.
KERNEL_FLAGS = {"SkylakeX": {"avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd"}}


def test_scripted_style_and_diversity_zero_agree_bit_for_bit(env_mod):
    """The scripted expert and the teleoperator model at diversity 0 give the same actions and states."""
    from lerobot_predvla.sims.libero.expert.teleop import TELEOP
    from lerobot_predvla.sims.libero.record import episode_seed
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec(SUITE, TASK_ID), init_noise=env_mod.OFFICIAL_INIT_NOISE)
    seed = episode_seed(0, TASK_ID, 0)
    scripted = run_episode(env, seed, CAP, "wrist_centre")
    teleop0 = run_episode(env, seed, CAP, "wrist_centre", teleop=TELEOP.at(0.0))
    env.close()
    assert scripted.success and np.array_equal(scripted.actions, teleop0.actions)
    assert np.array_equal(scripted.states, teleop0.states)


def test_the_scripted_style_reproduces_the_committed_dataset_under_its_openblas_kernels(env_mod):
    """The first demonstration of task 0 of the Table 2 dataset (seed 0, arm start noise 0.02, wrist_centre),
    regenerated under the OpenBLAS kernels its fingerprint was taken under (OPENBLAS_CORETYPE), gives its actions and
    states bit for bit, on whatever processor runs those kernels."""
    from lerobot_predvla.utils.versions import cpu_flags

    fingerprint = json.loads(FINGERPRINT.read_text())
    kernel = fingerprint["versions"]["openblas_coretype"]
    if not KERNEL_FLAGS[kernel] <= cpu_flags():
        pytest.skip(f"this processor cannot run OpenBLAS's {kernel} kernels (needs {sorted(KERNEL_FLAGS[kernel])})")
    recorded = fingerprint["files"][f"{env_mod.task_spec(SUITE, TASK_ID).name}_demo.hdf5"]["demo_0"]
    pinned = {**os.environ, "OPENBLAS_CORETYPE": kernel}
    done = subprocess.run([sys.executable, "-c", REGENERATE], capture_output=True, text=True, env=pinned, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-3:] == [kernel, recorded["actions"], recorded["states"]]


def test_a_teleop_demonstration_succeeds_within_the_step_cap(env_mod):
    from lerobot_predvla.sims.libero.expert.teleop import TELEOP
    from lerobot_predvla.sims.libero.record import episode_seed
    from lerobot_predvla.sims.libero.rollout import run_episode
    from research.demo_styles import noop_mask

    env = env_mod.make_env(env_mod.task_spec(SUITE, TASK_ID), init_noise=env_mod.OFFICIAL_INIT_NOISE)
    seed = episode_seed(0, TASK_ID, 0)
    episode = run_episode(env, seed, CAP, "wrist_centre", teleop=TELEOP)
    again = run_episode(env, seed, CAP, "wrist_centre", teleop=TELEOP)
    env.close()
    assert episode.success, episode.note
    assert len(episode.actions) < CAP and np.abs(episode.actions).max() <= 1.0
    assert noop_mask(episode.actions).any()  # the operator idles before moving
    assert np.array_equal(episode.actions, again.actions)  # all randomness from the episode's seed


def test_shift_objects_moves_each_object_by_its_offset_and_shifted_demonstrations_succeed(env_mod):
    from lerobot_predvla.sims.libero.expert.teleop import TELEOP
    from lerobot_predvla.sims.libero.placement import movable_objects, object_positions, shift_objects
    from lerobot_predvla.sims.libero.rollout import run_episode

    env = env_mod.make_env(env_mod.task_spec(SUITE, TASK_ID))
    env.reset()
    env.set_init_state(env_mod.official_init_states(SUITE, TASK_ID)[0])
    names = movable_objects(env)
    before = object_positions(env)
    shift_objects(env, {names[0]: np.array([0.02, -0.01])})
    moved = object_positions(env) - before
    np.testing.assert_allclose(moved[0], [0.02, -0.01, 0.0], atol=1e-9)
    np.testing.assert_allclose(moved[1:], 0.0, atol=1e-9)
    with pytest.raises(KeyError, match="not a movable object"):
        shift_objects(env, {"no_such_object": np.zeros(2)})

    episode = run_episode(env, 1000, CAP, teleop=TELEOP, placement_spread=0.03)
    plain = run_episode(env, 1000, 1)
    env.close()
    assert episode.success, episode.note
    env2 = env_mod.make_env(env_mod.task_spec(SUITE, TASK_ID))
    starts = []
    for state in (episode.states[0], plain.states[0]):
        env2.sim.set_state_from_flattened(state)
        env2.sim.forward()
        starts.append(object_positions(env2)[:, :2])
    env2.close()
    offsets = np.linalg.norm(starts[0] - starts[1], axis=1)  # same reset, with and without the shift
    assert offsets.max() > 0.01 and offsets.max() < 2 * np.sqrt(2) * 0.03 + 0.005, offsets
