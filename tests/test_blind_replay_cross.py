"""`predvla blind-replay --cross-task`: scenes, resumption and the matrix report on made-up files (no simulator),
and one plan replayed on another task of libero_goal for real (simulator)."""

import json

import pytest

from lerobot_predvla.cli import blind_replay as cli
from lerobot_predvla.cli.main import build_parser
from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.sims.libero import blind_replay, blind_replay_cross, cross_task_report
from lerobot_predvla.sims.libero.blind_replay import Settings
from lerobot_predvla.utils.io import atomic_write_json

SUITE = "libero_goal"
BDDL = """(define (problem LIBERO_Kitchen_Tabletop_Manipulation)
  (:domain robosuite)
  (:language {language})
  (:fixtures
    main_table - table
    {fixture} - flat_stove
  )
  (:obj_of_interest
    {interest}
  )
  (:init
    (On plate_1 main_table_plate_init_region)
  )
  (:goal
    ({goal})
  )
)
"""


def test_scene_text_keeps_the_scene_and_drops_instruction_objects_of_interest_and_goal():
    one = BDDL.format(language="turn on the stove", fixture="flat_stove_1", interest="flat_stove_1",
                      goal="Turnon flat_stove_1")
    other = BDDL.format(language="put the bowl on the plate", fixture="flat_stove_1", interest="akita_black_bowl_1\n"
                        "    plate_1", goal="On akita_black_bowl_1 plate_1")
    elsewhere = BDDL.format(language="turn on the stove", fixture="flat_stove_2", interest="flat_stove_1",
                            goal="Turnon flat_stove_1")
    assert blind_replay_cross.scene_text(one) == blind_replay_cross.scene_text(other)
    assert blind_replay_cross.scene_text(one) != blind_replay_cross.scene_text(elsewhere)
    assert "(:init" in blind_replay_cross.scene_text(one) and "Turnon" not in blind_replay_cross.scene_text(one)


def test_the_flag_parses_with_and_without_ids_and_the_command_line_round_trips():
    parser = build_parser()
    plain = parser.parse_args(["blind-replay", "--cross-task", "--suites", SUITE, "--states", "1-2"])
    assert tuple(plain.cross_task) == cli.ALL_OTHERS and plain.out is None
    plain.out = cli.default_out(plain)
    assert plain.out == blind_replay_cross.DEFAULT_CROSS_OUT
    assert cli.command_line(plain) == "predvla blind-replay --cross-task --suites libero_goal --states 1,2"
    named = parser.parse_args(["blind-replay", "--cross-task", "3,5", "--tasks", "0", "--states", "1",
                               "--out", "x"])
    assert named.cross_task == [3, 5]
    assert cli.command_line(named).startswith("predvla blind-replay --cross-task 3,5 --tasks 0 --states 1")
    assert parser.parse_args(["blind-replay"]).cross_task is None
    with pytest.raises(SystemExit):
        parser.parse_args(["blind-replay", "--cross-task", "a"])


def _evaluated(out, task_id: int, plans: dict[int, list], settings: Settings) -> None:
    """A made-up per-evaluated-task file: plan task -> success steps (None: failure) on `settings.states`."""
    atomic_write_json(blind_replay_cross.evaluated_path(out, SUITE, task_id), {
        "suite": SUITE, "task_id": task_id, "task_name": f"task_{task_id}", "language": f"do task {task_id}",
        "settings": settings.as_dict(), "plans": {str(a): {
            "plan_task_name": f"task_{a}", "states": list(settings.states),
            "success_step": {str(s): v for s, v in zip(settings.states, steps, strict=True)},
            "successes": sum(v is not None for v in steps), "episodes": len(steps), "seconds": 1.0}
            for a, steps in plans.items()}})


def _own(own_out, task_id: int, steps: dict[int, int | None], settings: Settings) -> None:
    """A made-up own-task blind-replay file whose state-0 plan succeeded at `steps` (state -> step or None)."""
    states = sorted(steps)
    own_settings = Settings(states=tuple(states), source_state=settings.source_state, cap=settings.cap,
                            seed=settings.seed)
    atomic_write_json(blind_replay.task_path(own_out, SUITE, task_id), {
        "task_id": task_id, "settings": own_settings.as_dict(), "plans": {"state0": {
            "states": states, "success_step": {str(s): v for s, v in steps.items()},
            "successes": sum(v is not None for v in steps.values()), "episodes": len(steps)}}})


def test_the_report_sets_other_plans_beside_the_own_plan_on_the_same_states(tmp_path):
    out, own_out = tmp_path / "cross", tmp_path / "own"
    settings = Settings(states=(1, 2), cap=600)
    _evaluated(out, 0, {1: [None, 50], 2: [None, None]}, settings)
    _evaluated(out, 1, {0: [None, None], 2: [None, None]}, settings)
    _evaluated(out, 2, {0: [None, None], 1: [None, None]}, settings)
    _own(own_out, 0, {1: 80, 2: 90, 3: None, 4: 70}, settings)  # 2/2 on states 1-2, 3/4 on its own states
    _own(own_out, 1, {1: None, 2: 60, 3: 60, 4: None}, settings)
    _own(own_out, 2, {1: None, 2: None, 3: None, 4: None}, settings)
    report = cross_task_report.write_cross_report(out, "predvla blind-replay --cross-task", own_out)[SUITE]
    t0 = report["tasks"]["0"]
    assert t0["by_plan"] == {"1": {"successes": 1, "episodes": 2}, "2": {"successes": 0, "episodes": 2}}
    assert t0["other_plans"] == {"successes": 1, "episodes": 4}
    assert t0["own_plan_same_states"] == {"successes": 2, "episodes": 2}
    assert t0["own_plan"] == {"successes": 3, "episodes": 4, "states": [1, 2, 3, 4]}
    assert report["other_plans"] == {"successes": 1, "episodes": 12}
    assert report["own_plan_same_states"] == {"successes": 3, "episodes": 6}
    assert cross_task_report.ratio_text(t0["other_plans"], t0["own_plan_same_states"]) == "0.25"
    assert cross_task_report.ratio_text(report["tasks"]["2"]["other_plans"],
                                        report["tasks"]["2"]["own_plan_same_states"]) == "own 0"
    text = (out / cross_task_report.REPORT_MD).read_text()
    assert "| 0 | 2/2 (100.0%) | 3/4 (75.0%) | 1/4 (25.0%) | 0.25 | 0.33 | 1 (1) | task_0 |" in text
    assert "| 1 | 1/2 | *1/2* | 0/2 |" in text  # plan task 1's row: on task 0, its own (diagonal), on task 2
    assert json.loads((out / cross_task_report.REPORT_JSON).read_text())[SUITE]["states"] == [1, 2]
    assert (out / cross_task_report.FIGURE).stat().st_size > 0
    plan_tasks, evaluated, grid = cross_task_report.matrix(report)
    assert plan_tasks == evaluated == ["0", "1", "2"] and grid[1, 0] == 50 and grid[0, 0] == 100

    # An own-task file under other settings is not set beside: it would be other episodes.
    _own(own_out, 0, {1: 80, 2: 90}, Settings(states=(1, 2), cap=300))
    assert cross_task_report.collect(out, own_out)[SUITE]["tasks"]["0"]["own_plan_same_states"] is None


def test_pairs_skip_finished_plans_and_other_scenes_and_refuse_other_settings(tmp_path, monkeypatch):
    monkeypatch.setattr(blind_replay_cross, "scene_groups", lambda suite, ids: [[0, 1, 2], [3]])
    settings = Settings(states=(1,))
    _evaluated(tmp_path, 1, {0: [None]}, settings)
    pairs = blind_replay_cross.pairs_to_run(tmp_path, SUITE, [0, 1, 3], [0, 1, 3], settings, strict=False)
    assert [(p.plan_task, p.evaluated_task) for p in pairs] == [(1, 0)]
    with pytest.raises(ValueError, match="different scenes"):
        blind_replay_cross.pairs_to_run(tmp_path, SUITE, [0], [3], settings, strict=True)
    with pytest.raises(ValueError, match="other settings"):
        blind_replay_cross.pairs_to_run(tmp_path, SUITE, [0], [1], Settings(states=(2,)), strict=True)


@pytest.mark.simulator
def test_libero_goal_is_one_scene_and_a_plan_is_judged_by_the_evaluated_tasks_goal(tmp_path):
    assert blind_replay_cross.scene_groups(SUITE, list(range(10))) == [list(range(10))]
    out = tmp_path / "cross"
    # Task 7's plan (turn on the stove) replayed on task 1 (put the bowl on the stove): one state, a short cap.
    args = ["blind-replay", "--cross-task", "1", "--suites", SUITE, "--tasks", "7", "--states", "1", "--cap", "100",
            "--own-out", str(tmp_path / "none"), "--out", str(out)]
    assert predvla_main(args) == 0
    plan = json.loads(blind_replay_cross.plan_path(out, SUITE, 7).read_text())
    assert plan["task_name"] == "turn_on_the_stove" and plan["source_success"]
    assert len(plan["plan"]) == plan["source_steps"] <= 100
    evaluated = json.loads(blind_replay_cross.evaluated_path(out, SUITE, 1).read_text())
    assert evaluated["task_name"] == "put_the_bowl_on_the_stove" and list(evaluated["plans"]) == ["7"]
    row = evaluated["plans"]["7"]
    # Turning the stove on leaves the bowl where it was: task 1's goal is not met (task 7's would be).
    assert row["success_step"] == {"1": None} and (row["successes"], row["episodes"]) == (0, 1)
    report = json.loads((out / cross_task_report.REPORT_JSON).read_text())[SUITE]
    assert report["tasks"]["1"]["own_plan_same_states"] is None and report["other_plans"]["episodes"] == 1
    before = blind_replay_cross.evaluated_path(out, SUITE, 1).read_bytes()
    assert predvla_main(args) == 0  # finished: nothing runs again
    assert blind_replay_cross.evaluated_path(out, SUITE, 1).read_bytes() == before


def test_the_report_command_names_the_suites_and_tasks_its_folder_holds(tmp_path):
    """report.md's "Reproduce" line repeats the run that wrote OUT, not a run of every task."""
    args = build_parser().parse_args(["blind-replay", "--suites", "libero_object", "--tasks", "2,3,6",
                                      "--resets-seed", "3000", "--episodes", "10", "--out", str(tmp_path)])
    for task in (2, 3, 6):
        path = blind_replay.task_path(tmp_path, "libero_object", task)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("{}")
    command = cli.command_for_report(args)
    assert command.startswith("predvla blind-replay --suites libero_object --tasks 2,3,6 ")
    assert "--resets-seed 3000 --episodes 10" in command
    for task in range(10):  # the whole suite held: no --tasks
        blind_replay.task_path(tmp_path, "libero_object", task).write_text("{}")
    assert "--tasks" not in cli.command_for_report(args) and "--suites libero_object" in cli.command_for_report(args)
    path = blind_replay.task_path(tmp_path, "libero_goal", 0)  # another suite with other tasks: one line per suite
    path.parent.mkdir(parents=True)
    path.write_text("{}")
    lines = cli.command_for_report(args).splitlines()
    assert len(lines) == 2 and "--suites libero_goal --tasks 0 " in lines[1] and "--tasks" not in lines[0]
