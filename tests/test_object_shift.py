"""Shifted objects (`--env.object_shift_cm`) and LIBERO-PRO / LIBERO-plus variants (`--env.task=<variant>`).

The unit tests cover the direction patterns, the goal parsing, the variant names and the eval_info section; the
simulator tests build real environments: a shifted object rests where it was put and its shift is recorded, each
variant family that loads runs a few steps, and `lerobot-eval` writes the shifts into eval_info.json.
"""

from pathlib import Path

import numpy as np
import pytest
from eval_factory import open_loop_eval

from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv
from lerobot_predvla.sims.libero.object_shift import ShiftSpec, pick_and_place, settle_motion, shift_summary
from lerobot_predvla.sims.libero.variants import parse_variant, task_key

IDLE = np.array([[0, 0, 0, 0, 0, 0, -1]], dtype=np.float32)


# ----- patterns and bookkeeping (no simulator) -----------------------------------------------------------------------
def test_ring_turns_once_round_every_n_episodes():
    spec = ShiftSpec(object_cm=4, directions=8)
    assert [spec.direction_degrees(k) for k in range(9)] == [0, 45, 90, 135, 180, 225, 270, 315, 0]
    for k in range(8):
        degrees, offset = spec.offsets(k)["object"]
        assert np.linalg.norm(offset) == pytest.approx(0.04)
        assert np.degrees(np.arctan2(offset[1], offset[0])) % 360 == pytest.approx(degrees)


def test_cross_cycles_plus_x_minus_x_plus_y_minus_y():
    spec = ShiftSpec(object_cm=2, pattern="cross")
    offsets = [spec.offsets(k)["object"][1] for k in range(5)]
    np.testing.assert_allclose(offsets, [[0.02, 0], [-0.02, 0], [0, 0.02], [0, -0.02], [0.02, 0]], atol=1e-12)


def test_target_moves_opposite_the_object_and_only_when_asked():
    spec = ShiftSpec(object_cm=4, target_cm=3, directions=4)
    moves = spec.offsets(1)
    assert moves["object"][0] == 90 and moves["target"][0] == 270
    np.testing.assert_allclose(moves["target"][1], [0, -0.03], atol=1e-12)
    assert set(ShiftSpec(object_cm=4).offsets(0)) == {"object"}
    assert set(ShiftSpec(target_cm=4).offsets(0)) == {"target"}
    assert not ShiftSpec().active and ShiftSpec(target_cm=1).active


@pytest.mark.parametrize("kwargs, flag", [({"object_cm": -1}, "object_shift_cm"), ({"pattern": "spiral"}, "pattern"),
                                          ({"directions": 0}, "directions"), ({"tolerance_cm": 0}, "tolerance")])
def test_bad_shift_settings_name_their_flag(kwargs, flag):
    with pytest.raises(ValueError, match=flag):
        ShiftSpec(**kwargs)


def test_shift_needs_the_official_init_states():
    with pytest.raises(ValueError, match="init_states=true"):
        PredVLALiberoEnv(task="libero_object", object_shift_cm=2, init_states=False)
    # the same check the simulator env makes when built directly (SparseRenderLiberoEnv)
    with pytest.raises(ValueError, match="init_states=true"):
        ShiftSpec(target_cm=1).check_init_states(False)
    ShiftSpec(object_cm=2).check_init_states(True)
    ShiftSpec().check_init_states(False)  # no shift asked for: nothing to check


def test_object_to_pick_is_the_first_in_or_on_predicate_in_the_experts_order():
    assert pick_and_place([["In", "x"], ["in", "soup_1", "basket_1_contain_region"]]) == ("soup_1",
                                                                                         "basket_1_contain_region")
    assert pick_and_place([["on", "pot_1", "stove_1_cook_region"], ["turnon", "stove_1"]])[0] == "pot_1"
    with pytest.raises(ValueError, match="no In/On predicate"):
        pick_and_place([["open", "drawer_1"]])


def test_settle_motion_measures_slide_lift_and_tilt():
    upright = np.array([0.1, 0.2, 0.0, 1, 0, 0, 0])
    tipped = np.array([0.1, 0.23, 0.05, np.cos(np.pi / 8), np.sin(np.pi / 8), 0, 0])  # 45 degrees about x
    assert settle_motion(upright, tipped) == {"xy_cm": 3.0, "dz_cm": 5.0, "tilt_deg": 45.0}


class FakeVectorEnv:
    def __init__(self, records):
        self.records = records

    def get_attr(self, name):
        if name != "shift_records":
            raise AttributeError(name)
        return self.records


def test_shift_summary_lists_every_episode_and_the_unsettled_ones():
    spec = {"object_cm": 4}
    record = {"task": "t", "spec": spec, "bodies": []}
    envs = {"libero_object": {0: FakeVectorEnv([[{**record, "task_id": 0, "episode_ix": 1, "settled": True}],
                                                [{**record, "task_id": 0, "episode_ix": 0, "settled": False}]])}}
    summary = shift_summary(envs)
    assert summary["spec"] == spec
    assert [e["episode_ix"] for e in summary["episodes"]] == [0, 1]
    assert summary["unsettled_episodes"] == [{"suite": "libero_object", "task_id": 0, "episode_ix": 0}]
    assert shift_summary({"libero_object": {0: FakeVectorEnv([[]])}}) is None


def test_variant_names():
    name = parse_variant("libero_object_pro_temp_x0.1")
    assert (name.suite, name.family, name.variant) == ("libero_object", "pro", "temp_x0.1")
    assert parse_variant("libero_object_plus_language_3").family == "plus"
    assert parse_variant("libero_object") is None and parse_variant("libero_90_pro_swap") is None
    assert task_key("FLOOR_SCENE10_pick_the_butter_and_place_it_in_the_basket") == \
        "pick_up_the_butter_and_place_it_in_the_basket"


# ----- in the simulator --------------------------------------------------------------------------------------------
def _episode(task: str, steps: int = 3, **env_kwargs):
    """One counted episode of task 0 (reset as lerobot-eval does, `steps` idle steps): the vector env, the first
    observation's info and the last step's info."""
    cfg = PredVLALiberoEnv(task=task, task_ids=[0], episode_length=steps + 2, render_interval=1000, **env_kwargs)
    venv = cfg.create_envs(1)[task][0]
    _, reset_info = venv.reset(seed=[0], options={"lerobot_new_rollout": True})
    info = None
    for _ in range(steps):
        *_, info = venv.step(IDLE)
    return venv, reset_info, info


@pytest.mark.simulator
def test_shifted_object_and_target_rest_where_they_were_put_and_the_shifts_are_recorded():
    from lerobot_predvla.sims.libero.env import official_init_states
    from lerobot_predvla.sims.libero.object_shift import pose

    venv, reset_info, _ = _episode("libero_object", object_shift_cm=4, target_shift_cm=3, object_shift_pattern="cross")
    try:
        env = venv.envs[0].unwrapped
        (record,) = env.shift_records
        assert record["episode_ix"] == 0 and record["init_state"] == 0 and record["settled"]
        official = official_init_states("libero_object", 0)[0]
        bodies = {body["role"]: body for body in record["bodies"]}
        for role, name, direction, offset in (("object", "alphabet_soup_1", 0, [0.04, 0]),
                                              ("target", "basket_1", 180, [-0.03, 0])):
            body = bodies[role]
            assert (body["name"], body["direction_deg"]) == (name, direction)
            # placed poses are recorded to 1 um
            address = env._env.sim.model.get_joint_qpos_addr(env._env.env.objects_dict[name].joints[0])[0]
            np.testing.assert_allclose(body["placed"][:2], official[1 + address:3 + address] + offset, atol=1e-6)
            now = pose(env._env, name)  # after the reset's settle steps and three idle steps
            assert np.linalg.norm(now[:2] - np.asarray(body["placed"][:2])) < 0.005
        assert reset_info["shift_settled"][0]
    finally:
        venv.close()


@pytest.mark.simulator
def test_a_shift_into_a_neighbour_is_reported_as_unsettled():
    """Task 2's salad dressing shifted 10 cm along -y (episode 3 of the cross) lands on the cream cheese: reported,
    not silently used."""
    cfg = PredVLALiberoEnv(task="libero_object", task_ids=[2], episode_length=3, render_interval=1000,
                           object_shift_cm=10, object_shift_pattern="cross")
    venv = cfg.create_envs(4)["libero_object"][2]
    try:
        venv.reset(seed=[0] * 4, options={"lerobot_new_rollout": True})
        by_episode = {r["episode_ix"]: r for records in venv.get_attr("shift_records") for r in records}
        assert sorted(by_episode) == [0, 1, 2, 3]
        minus_y = by_episode[3]
        assert minus_y["bodies"][0]["name"] == "salad_dressing_1" and minus_y["bodies"][0]["direction_deg"] == 270
        assert not minus_y["settled"] and minus_y["bodies"][0]["touching"] == ["cream_cheese_1"]
        unsettled = shift_summary({"libero_object": {2: venv}})["unsettled_episodes"]
        assert {"suite": "libero_object", "task_id": 2, "episode_ix": 3} in unsettled
    finally:
        venv.close()


@pytest.mark.simulator
@pytest.mark.parametrize("task, instruction", [
    ("libero_object_pro_temp_x0.1", "pick up the alphabet soup and place it in the basket"),
    ("libero_object_pro_swap", "pick up the alphabet soup and place it in the basket"),
    ("libero_object_pro_lan", "grab alphabet soup and put it into basket"),
    ("libero_object_pro_with_yellow_book", "pick up the alphabet soup and place it in the basket"),
    ("libero_object_plus_language_3", "Please put the alphabet soup in the basket"),
])
def test_variant_runs_a_few_steps(task, instruction):
    venv, _, info = _episode(task)
    try:
        assert venv.call("task_description") == (instruction,)
        assert "fault" not in info and venv.get_attr("faults") == ([],)
        assert Path(venv.envs[0].unwrapped._task_bddl_file).is_file()
    finally:
        venv.close()


@pytest.mark.simulator
@pytest.mark.parametrize("task, missing", [("libero_object_plus_light_3", "problem class"),
                                           ("libero_object_pro_with_mug", "object class 'libero_mug_yellow'"),
                                           ("libero_object_pro_temp_y0.5", "missing or empty"),
                                           ("libero_object_plus_add_3", "language_<n>"),
                                           ("libero_object_pro_nothing", "LIBERO-PRO has no folder")])
def test_variants_that_do_not_load_say_why(task, missing):
    with pytest.raises(ValueError, match=missing):
        PredVLALiberoEnv(task=task).create_envs(1)


@pytest.mark.simulator
def test_lerobot_eval_writes_the_shifts_into_eval_info(tmp_path):
    """The committed checkpoint in exact open loop, one 3-step episode with the object shifted 2 cm."""
    shifts = open_loop_eval(tmp_path / "eval", "[1]", "--env.object_shift_cm=2")["predvla_shifts"]
    assert shifts["spec"]["object_cm"] == 2 and shifts["unsettled_episodes"] == []
    (episode,) = shifts["episodes"]
    assert episode["task_id"] == 1 and episode["bodies"][0]["name"] == "cream_cheese_1"


@pytest.mark.simulator
def test_counted_episodes_keep_their_init_states_across_gymnasiums_autoresets():
    """Sub-environment 0 of 2 ends early (a non-finite action faults it), so Gymnasium resets it on the next step for
    an extra episode lerobot-eval discards; lerobot-eval's next rollout still starts it from official init state 2."""
    cfg = PredVLALiberoEnv(task="libero_object", task_ids=[0], episode_length=6, render_interval=1000,
                           object_shift_cm=1)
    venv = cfg.create_envs(2)["libero_object"][0]
    new_rollout = {"lerobot_new_rollout": True}
    try:
        venv.reset(seed=[0, 0], options=new_rollout)
        *_, terminated, _, _ = venv.step(np.concatenate([np.full_like(IDLE, np.nan), IDLE]))
        assert terminated.tolist() == [True, False]
        venv.step(np.concatenate([IDLE, IDLE]))  # Gymnasium's autoreset of sub-environment 0
        venv.reset(seed=[0, 0], options=new_rollout)
        assert [r["init_state"] for r in venv.envs[0].unwrapped.shift_records] == [0, 2]
        assert [r["init_state"] for r in venv.envs[1].unwrapped.shift_records] == [1, 3]
    finally:
        venv.close()
