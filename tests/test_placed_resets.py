"""Varied placements at evaluation (`--env.placement_spread_cm`): lerobot-eval's episodes start where `predvla demos
--placement-spread-cm` demonstrations of the same seeds start. The option's checks run without the simulator; the
simulator tests reset real environments as lerobot-eval does and set them beside the demonstrations' starts and the
blind replay's (`predvla blind-replay --resets-seed`)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv
from lerobot_predvla.sims.libero.object_shift import shift_summary

CHECKPOINT = Path(__file__).parents[1] / "checkpoints" / "predvla_libero_object_reading"
SUITE, TASK_ID, SEED, SPREAD_CM = "libero_object", 0, 3000, 3.0
NEW_ROLLOUT = {"lerobot_new_rollout": True}  # what lerobot-eval's rollout passes to every reset it counts


@pytest.mark.parametrize("kwargs, message", [
    ({"placement_spread_cm": -1.0, "init_states": False}, r"placement_spread_cm must be >= 0"),
    ({"placement_spread_cm": 3.0}, r"placement_spread_cm .* needs --env.init_states=false"),
    ({"placement_spread_cm": 3.0, "init_states": False, "object_shift_cm": 4.0},
     r"placement_spread_cm cannot be combined with --env.object_shift_cm"),
    ({"placement_spread_cm": 3.0, "init_states": False, "target_shift_cm": 4.0},
     r"placement_spread_cm cannot be combined"),
])
def test_bad_placement_settings_name_their_flags(kwargs, message):
    with pytest.raises(ValueError, match=message):
        PredVLALiberoEnv(task=SUITE, **kwargs)


def test_the_option_reaches_the_environments():
    cfg = PredVLALiberoEnv(task=SUITE, init_states=False, placement_spread_cm=SPREAD_CM)
    assert cfg.gym_kwargs["placement_spread_cm"] == SPREAD_CM
    assert PredVLALiberoEnv(task=SUITE).gym_kwargs["placement_spread_cm"] == 0


def _reset(spread_cm: float, n_envs: int):
    """Batch 0 of lerobot-eval --seed=SEED on task TASK_ID: sub-environment j reset with seed SEED + j; the vector
    env (to close), and the objects' positions after the reset's settle steps."""
    from lerobot_predvla.sims.libero.placement import object_positions

    cfg = PredVLALiberoEnv(task=SUITE, task_ids=[TASK_ID], episode_length=5, render_interval=1000, init_states=False,
                           placement_spread_cm=spread_cm)
    venv = cfg.create_envs(n_envs)[SUITE][TASK_ID]
    _, info = venv.reset(seed=[SEED + j for j in range(n_envs)], options=NEW_ROLLOUT)
    return venv, info, [object_positions(env.unwrapped._env) for env in venv.envs]


def _demonstration_start(seed: int, spread_cm: float, init_noise: float, settle_steps: int = 0):
    """Where `predvla demos --placement-spread-cm spread_cm` puts the objects for episode seed `seed` (the randomised
    reset and `placement.episode_shift` of `rollout.run_episode`): the offsets, and the objects' positions after the
    shift (and `settle_steps` idle steps)."""
    from lerobot_predvla.sims.libero.env import make_env, random_reset, task_spec
    from lerobot_predvla.sims.libero.placement import episode_shift, object_positions
    from lerobot_predvla.sims.libero.rollout import IDLE

    env = make_env(task_spec(SUITE, TASK_ID), init_noise=init_noise)
    try:
        random_reset(env, seed)
        offsets = episode_shift(env, seed, spread_cm / 100) if spread_cm > 0 else {}
        for _ in range(settle_steps):
            env.step(IDLE)
        return offsets, object_positions(env)
    finally:
        env.close()


@pytest.mark.simulator
def test_episodes_start_from_the_demonstrations_shifted_placements():
    """Two episodes at 3 cm: each is shifted by the offsets a D3 demonstration (arm start noise 0.02) of episode seed
    SEED + i gets, from the same placement; the records say so and that the objects settled."""
    from lerobot_predvla.sims.libero.env import OFFICIAL_INIT_NOISE

    venv, info, _ = _reset(SPREAD_CM, 2)
    try:
        records = [r for env in venv.envs for r in env.unwrapped.shift_records]
        summary = shift_summary({SUITE: {TASK_ID: venv}})
    finally:
        venv.close()
    assert [(r["episode_ix"], r["seed"]) for r in records] == [(0, SEED), (1, SEED + 1)]
    assert summary["spec"] == {"placement_spread_cm": SPREAD_CM} and len(summary["episodes"]) == 2
    for record in records:
        offsets, placed = _demonstration_start(record["seed"], SPREAD_CM, OFFICIAL_INIT_NOISE)
        assert list(record["offsets_m"]) == list(offsets) and len(offsets) == 7  # every movable object of the task
        for name, offset in offsets.items():
            np.testing.assert_allclose(record["offsets_m"][name], offset, atol=1e-6)
        np.testing.assert_allclose(list(record["placed_xy_m"].values()), placed[:, :2], atol=1e-6)
        assert record["settled"] and max(record["settle_xy_cm"].values()) < 1.0
    assert not np.allclose(list(records[0]["offsets_m"].values()), list(records[1]["offsets_m"].values()))
    assert info["shift_settled"].tolist() == [True, True]
    assert summary["unsettled_episodes"] == []


@pytest.mark.simulator
def test_no_spread_leaves_the_randomised_reset_as_it_was():
    """At 0 cm nothing is shifted or recorded: the objects stand, after LeRobot's 10 settle steps, where the
    demonstrations' unshifted reset of the same seed puts them after as many idle steps."""
    venv, _, (positions,) = _reset(0.0, 1)
    try:
        assert venv.envs[0].unwrapped.placements is None and venv.envs[0].unwrapped.shift_records == []
    finally:
        venv.close()
    _, expected = _demonstration_start(SEED, 0.0, init_noise=0.0, settle_steps=10)
    np.testing.assert_allclose(positions, expected, atol=1e-9)


@pytest.mark.simulator
def test_lerobot_eval_seeds_episode_i_with_seed_plus_i_across_batches(tmp_path):
    """The real lerobot-eval, two 3-step episodes in two batches of one (the committed checkpoint, exact open loop):
    episode i's reset seed is --seed + i, and its placement record in eval_info.json has that seed's offsets."""
    out = tmp_path / "eval"
    command = [str(Path(sys.executable).with_name("lerobot-eval")), f"--policy.path={CHECKPOINT}",
               "--policy.device=cpu", "--policy.er_iterations=0", "--env.type=predvla_libero", f"--env.task={SUITE}",
               f"--env.task_ids=[{TASK_ID}]", "--env.episode_length=3", "--env.render_interval=100000",
               "--env.init_states=false", f"--env.placement_spread_cm={SPREAD_CM}", f"--seed={SEED}",
               "--eval.n_episodes=2", "--eval.batch_size=1", "--eval.use_async_envs=false", f"--output_dir={out}"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    info = json.loads((out / "eval_info.json").read_text())
    assert len(info["per_task"][0]["metrics"]["successes"]) == 2
    shifts = info["predvla_shifts"]
    assert [(e["episode_ix"], e["seed"]) for e in shifts["episodes"]] == [(0, SEED), (1, SEED + 1)]
    for episode in shifts["episodes"]:
        offsets, _ = _demonstration_start(episode["seed"], SPREAD_CM, init_noise=0.0)
        np.testing.assert_allclose(list(episode["offsets_m"].values()), list(offsets.values()), atol=1e-6)


@pytest.mark.simulator
@pytest.mark.parametrize("spread_cm", [0.0, SPREAD_CM])
def test_blind_replay_on_resets_starts_where_the_evaluation_env_starts(spread_cm):
    """`predvla blind-replay --resets-seed SEED [--placement-spread-cm 3]`: episode i of its replays starts from the
    simulator state (after the settle steps) in which lerobot-eval's episode i of the same seed starts, on one env that
    has run an official start and a few steps before (as it has recorded a plan), with the evaluation's placement
    record."""
    from lerobot_predvla.sims.libero import blind_replay
    from lerobot_predvla.sims.libero.env import make_env, official_init_states, task_spec
    from lerobot_predvla.sims.libero.eval_resets import ResetSpec
    from lerobot_predvla.sims.libero.rollout import IDLE

    venv, _, _ = _reset(spread_cm, 2)
    try:
        expected = [env.unwrapped._env.get_sim_state() for env in venv.envs]
        records = [r for env in venv.envs for r in env.unwrapped.shift_records]
    finally:
        venv.close()
    settings = blind_replay.Settings(states=(), resets=ResetSpec(seed=SEED, episodes=2, placement_spread_cm=spread_cm))
    env = make_env(task_spec(SUITE, TASK_ID))
    try:
        env.reset()
        env.set_init_state(official_init_states(SUITE, TASK_ID)[0])
        for _ in range(3):
            env.step(IDLE + 0.5)
        for episode, state in enumerate(expected):
            record = blind_replay.start(env, None, episode, settings)
            np.testing.assert_allclose(env.get_sim_state(), state, rtol=0, atol=1e-9)
            assert record["seed"] == SEED + episode
            if spread_cm:
                assert record["offsets_m"] == records[episode]["offsets_m"] and record["settled"]
                assert record["placed_xy_m"] == records[episode]["placed_xy_m"]
            else:
                assert set(record) == {"seed"} and records == []
        assert not np.allclose(expected[0], expected[1])  # two seeds, two starts
    finally:
        env.close()
