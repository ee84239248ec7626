"""`predvla blind-replay`: the command run for real on tiny settings (simulator), and its reference row in the
generated headline (no simulator)."""

import json
import shutil
from pathlib import Path

import pytest

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.report import ReportError, headline
from lerobot_predvla.sims.libero import blind_replay
from lerobot_predvla.sweep.eval_info import parse_eval_info
from lerobot_predvla.utils.io import atomic_write_json

REPO = Path(__file__).resolve().parents[1]
SUITE, TASK_ID, STATES, CAP = "libero_object", 0, (1, 2), 200


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One task, two replay states, a short cap: the command as a user runs it."""
    try:
        from lerobot_predvla.sims.libero.env import task_spec

        task_spec(SUITE, TASK_ID)
    except (RuntimeError, ImportError) as err:
        pytest.fail(f"LIBERO is not installed: run `make libero` ({err})")
    out = tmp_path_factory.mktemp("blind") / "blind_replay"
    args = ["blind-replay", "--suites", SUITE, "--tasks", str(TASK_ID), "--states", ",".join(map(str, STATES)),
            "--cap", str(CAP), "--out", str(out)]
    assert predvla_main(args) == 0
    return out, args


@pytest.mark.simulator
def test_tiny_run_writes_the_report_and_replays_each_plan_exactly_on_its_source(tiny_run, tmp_path):
    out, _ = tiny_run
    report = json.loads((out / blind_replay.REPORT_JSON).read_text())
    assert list(report) == [SUITE] and list(report[SUITE]) == [str(TASK_ID)]
    entry = report[SUITE][str(TASK_ID)]
    second = entry[blind_replay.NEAREST_MEAN_KEY]
    # The headline reads the report where the command writes it by default, with both plans' numbers.
    committed = tmp_path / blind_replay.DEFAULT_OUT / blind_replay.REPORT_JSON
    committed.parent.mkdir(parents=True)
    committed.write_text((out / blind_replay.REPORT_JSON).read_text())
    assert headline.load_blind_replay(tmp_path / blind_replay.DEFAULT_OUT) == report
    assert entry["source_state"] == 0 and entry["episodes"] == len(STATES) and entry["states"] == list(STATES)
    assert 0 <= entry["successes"] <= entry["episodes"]
    assert second["episodes"] == len(STATES) - len(second["excluded_states"])
    assert set(second["excluded_states"]) <= {second["source_state"]} & set(STATES)

    task = json.loads(blind_replay.task_path(out, SUITE, TASK_ID).read_text())
    for name, plan in task["plans"].items():
        assert plan["source_success"], f"the expert failed from the {name} plan's source: {plan['source_note']}"
        # The plan replayed blind on its own source state is the expert's episode again: success at the same step.
        assert plan["source_replay_step"] == plan["source_steps"] == len(plan["plan"])
        assert plan["successes"] == sum(step is not None for step in plan["success_step"].values())
        assert all(step is None or step <= CAP for step in plan["success_step"].values())
    # The nearest-mean source: the state nearest the mean placement over every official init state.
    nearest = task["nearest_mean"]
    assert task["plans"]["nearest_mean"]["source_state"] == nearest["state"]
    assert nearest["distance_m"] <= nearest["median_distance_m"] and nearest["init_states"] == 50

    text = (out / blind_replay.REPORT_MD).read_text()
    assert "predvla blind-replay" in text and f"{entry['successes']}/{entry['episodes']}" in text
    assert (out / blind_replay.FIGURE).stat().st_size > 0


@pytest.mark.simulator
def test_a_finished_task_is_not_run_again_and_other_settings_are_refused(tiny_run, monkeypatch, capsys):
    out, args = tiny_run
    path = blind_replay.task_path(out, SUITE, TASK_ID)
    before = path.read_bytes()

    def never(*_, **__):
        raise AssertionError("a finished task ran again")

    monkeypatch.setattr("lerobot_predvla.cli.blind_replay.run_task", never)
    assert predvla_main(args) == 0
    assert path.read_bytes() == before
    with pytest.raises(SystemExit, match="--out"):
        predvla_main([*args[:-4], "--cap", str(CAP + 1), "--out", str(out)])
    with pytest.raises(SystemExit, match="--source-state"):
        predvla_main(["blind-replay", "--states", "0,1", "--out", str(out)])


def _fake_report(tasks: int) -> dict:
    """A blind-replay report.json of `tasks` libero_object tasks with made-up counts."""
    entry = {}
    for t in range(tasks):
        second = {"successes": t, "episodes": 19 if t % 2 else 20, "source_state": 10 + t, "source_success": True,
                  "source_replay_success": True, "plan_steps": 140, "excluded_states": [10 + t] if t % 2 else []}
        entry[str(t)] = {"successes": 20 - t, "episodes": 20, "source_state": 0, "source_success": True,
                         "source_replay_success": True, "plan_steps": 140, "excluded_states": [],
                         "task_name": f"task {t}", "states": list(range(1, 21)), "cap": 600,
                         blind_replay.NEAREST_MEAN_KEY: second}
    return {SUITE: entry}


def test_headline_reference_row_comes_from_the_blind_replay_report(tmp_path):
    row_dir = "results/libero_object_cpu"
    shutil.copytree(REPO / "configs", tmp_path / "configs")
    shutil.copytree(REPO / row_dir / "runs/records", tmp_path / row_dir / "runs/records")
    shutil.copytree(REPO / row_dir / "runs/eval", tmp_path / row_dir / "runs/eval")
    shutil.copy(REPO / row_dir / "report.json", tmp_path / row_dir / "report.json")
    (tmp_path / "docs").mkdir()
    for name in (headline.README, headline.RESULTS_DOC):
        (tmp_path / name).write_text(f"intro\n{headline.HEADLINE_START}\n{headline.HEADLINE_END}\nend\n")
    headline.update_docs(tmp_path)
    assert "replayed blind" not in (tmp_path / headline.README).read_text()

    report = _fake_report(10)
    atomic_write_json(tmp_path / "results/blind_replay/report.json", report)
    assert len(headline.update_docs(tmp_path)) == 2
    readme, results = (tmp_path / headline.README).read_text(), (tmp_path / headline.RESULTS_DOC).read_text()
    s0 = sum(t["successes"] for t in report[SUITE].values())
    n0 = sum(t["episodes"] for t in report[SUITE].values())
    s1 = sum(t[blind_replay.NEAREST_MEAN_KEY]["successes"] for t in report[SUITE].values())
    n1 = sum(t[blind_replay.NEAREST_MEAN_KEY]["episodes"] for t in report[SUITE].values())
    row = next(line for line in readme.splitlines() if "one demonstration replayed blind" in line)
    assert f"| {100 * s0 / n0:.1f} ({s0}/{n0}); from the nearest-mean start {100 * s1 / n1:.1f} ({s1}/{n1}) |" in row
    assert "results/blind_replay/report.md" in row
    for suite, (paper, _) in headline.PAPER_OPEN_LOOP.items():  # per suite on the detailed page only
        assert f"| {suite} ({headline.SUITE_LABELS[suite]}) | {paper:.2f} |" in results
        assert f"| {suite} ({headline.SUITE_LABELS[suite]}) |" not in readme
    # The detailed page: per task beside the leading row's exact open loop, counted from its eval_info files.
    open_loop = {}
    for path in (tmp_path / row_dir / "runs/eval/predvla_cpu_8k_open_loop").rglob("eval_info.json"):
        for task, counts in parse_eval_info(path).items():
            s, n = open_loop.get(task, (0, 0))
            open_loop[task] = (s + counts["successes"], n + counts["episodes"])
    assert open_loop
    for task, t in report[SUITE].items():
        second = t[blind_replay.NEAREST_MEAN_KEY]
        s, n = open_loop[task]
        assert (f"| {task} | {t['successes']}/{t['episodes']} | {second['successes']}/{second['episodes']} "
                f"({second['source_state']}) | {s}/{n} |") in results
    assert headline.update_docs(tmp_path, check=True) == []

    (tmp_path / "results/blind_replay/report.json").write_text(json.dumps({SUITE: {"0": {"successes": 1}}}))
    with pytest.raises(ReportError, match="blind_replay/report.json"):
        headline.update_docs(tmp_path, check=True)


@pytest.mark.simulator
def test_replays_under_a_shift_record_each_states_shift_and_settling(tmp_path):
    """`--object-shift-cm`: the replays on official init states 0 and 1 start with the object moved as lerobot-eval's
    episodes 0 and 1 would (cross: +x, -x), and the task's file says where it went and that it settled; the settings
    name the shift. State 0, the state-0 plan's source, is a replay of its own once shifted."""
    out = tmp_path / "shifted"
    args = ["blind-replay", "--suites", SUITE, "--tasks", str(TASK_ID), "--states", "0,1", "--cap", str(CAP),
            "--object-shift-cm", "4", "--object-shift-pattern", "cross", "--out", str(out)]
    assert predvla_main(args) == 0
    task = json.loads(blind_replay.task_path(out, SUITE, TASK_ID).read_text())
    assert task["settings"]["shift"]["object_cm"] == 4 and task["settings"]["shift"]["pattern"] == "cross"
    plan = task["plans"]["state0"]
    for state, direction, offset in (("0", 0, [0.04, 0.0]), ("1", 180, [-0.04, 0.0])):
        (body,) = plan["shifts"][state]["bodies"]
        assert body["name"] == "alphabet_soup_1" and body["direction_deg"] == direction and body["offset_m"] == offset
        assert plan["shifts"][state]["settled"]
    assert plan["states"] == [0, 1] and plan["episodes"] == 2 and plan["excluded_states"] == []


def test_unshifted_settings_keep_the_form_the_committed_results_were_recorded_with():
    """A blind replay without a shift still finds the committed per-task results (same settings), so they are reused."""
    committed = json.loads((REPO / "results" / "blind_replay" / "tasks" / SUITE / "task0.json").read_text())
    assert committed["settings"] == blind_replay.Settings().as_dict()
    assert "shift" in blind_replay.Settings(shift=blind_replay.ShiftSpec(object_cm=2)).as_dict()


@pytest.mark.simulator
def test_teleop_style_replays_the_teleoperator_models_demonstration_and_names_it(tiny_run, tmp_path):
    """`--style teleop`: the plan from state 0 is the teleoperator model's demonstration, not the script's (it starts
    idle and takes another path), the one `research.demo_styles` measured (its committed blind replay: plan length and
    success steps on states 1 and 2); the task's settings, report.json and report.md name the style."""
    scripted = json.loads(blind_replay.task_path(tiny_run[0], SUITE, TASK_ID).read_text())["plans"]["state0"]
    out = tmp_path / "teleop"
    args = ["blind-replay", "--suites", SUITE, "--tasks", str(TASK_ID), "--states", ",".join(map(str, STATES)),
            "--cap", str(CAP), "--style", "teleop", "--out", str(out)]
    assert predvla_main(args) == 0
    task = json.loads(blind_replay.task_path(out, SUITE, TASK_ID).read_text())
    assert task["settings"]["style"] == "teleop" and task["settings"]["diversity"] == 1.0
    plan = task["plans"]["state0"]
    assert plan["plan"] != scripted["plan"] and plan["source_success"]
    assert not any(plan["plan"][0][:6]) and any(scripted["plan"][0][:6])  # the operator's idle start; the script moves
    measured = json.loads((REPO / "results/demonstrations/report.json").read_text())["blind"]["teleop"]
    assert plan["source_steps"] == measured["plan_steps"]
    assert plan["success_step"] == {str(s): measured["success_step"][str(s)] for s in STATES}
    entry = json.loads((out / blind_replay.REPORT_JSON).read_text())[SUITE][str(TASK_ID)]
    assert (entry["style"], entry["diversity"]) == ("teleop", 1.0)
    assert "teleoperator model" in (out / blind_replay.REPORT_MD).read_text()
    assert "--style teleop --diversity 1" in (out / blind_replay.REPORT_MD).read_text()
    scripted_entry = json.loads((tiny_run[0] / blind_replay.REPORT_JSON).read_text())[SUITE][str(TASK_ID)]
    assert scripted_entry["style"] == "scripted" and "diversity" not in scripted_entry


def test_a_plans_own_source_is_a_replay_state_only_when_shifted():
    plain = blind_replay.Settings(states=(0, 1, 2))
    shifted = blind_replay.Settings(states=(0, 1, 2), shift=blind_replay.ShiftSpec(object_cm=4))
    assert plain.replay_episodes(0) == [1, 2] and plain.excluded(0) == [0] and plain.excluded(5) == []
    assert shifted.replay_episodes(0) == [0, 1, 2] and shifted.excluded(0) == []
    on_resets = blind_replay.Settings(states=(), resets=blind_replay.ResetSpec(seed=3000, episodes=3))
    assert on_resets.replay_episodes(0) == [0, 1, 2] and on_resets.excluded(0) == []


def test_style_flags_are_checked_and_one_report_holds_one_style(tmp_path):
    with pytest.raises(SystemExit, match="--diversity 0.5 needs --style teleop"):
        predvla_main(["blind-replay", "--diversity", "0.5", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="--diversity must be >= 0"):
        predvla_main(["blind-replay", "--style", "teleop", "--diversity", "-1", "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="--style teleop are not supported"):
        predvla_main(["blind-replay", "--cross-task", "--style", "teleop", "--out", str(tmp_path)])
    scripted = blind_replay.task_path(tmp_path, SUITE, 3)
    atomic_write_json(scripted, {"settings": blind_replay.Settings().as_dict()})
    with pytest.raises(SystemExit, match="another style"):
        predvla_main(["blind-replay", "--suites", SUITE, "--tasks", "0", "--style", "teleop", "--out", str(tmp_path)])
    teleop = blind_replay.Settings(style="teleop", diversity=0.5).as_dict()
    assert (teleop["style"], teleop["diversity"]) == ("teleop", 0.5)
    assert blind_replay.Settings(diversity=0.5).as_dict() == blind_replay.Settings().as_dict()


@pytest.mark.simulator
def test_replays_on_randomised_resets_name_the_set_and_record_each_reset(tmp_path):
    """`--resets-seed 3000 --episodes 2 --placement-spread-cm 3`: each plan is replayed on episodes 0 and 1 of
    lerobot-eval's randomised resets of seed 3000 with the placement spread (where they start is
    tests/test_placed_resets.py's), still on its own source state too; the settings, the per-episode records,
    report.json's entries and report.md name the set."""
    out = tmp_path / "resets"
    args = ["blind-replay", "--suites", SUITE, "--tasks", str(TASK_ID), "--cap", "20", "--resets-seed", "3000",
            "--episodes", "2", "--placement-spread-cm", "3", "--out", str(out)]
    assert predvla_main(args) == 0
    task = json.loads(blind_replay.task_path(out, SUITE, TASK_ID).read_text())
    assert task["settings"]["resets"] == {"seed": 3000, "episodes": 2, "placement_spread_cm": 3.0, "settle_steps": 10}
    assert task["settings"]["states"] == [] and task["settings"]["settle_steps"] == blind_replay.SETTLE_STEPS
    for plan in task["plans"].values():
        assert plan["reset_episodes"] == [0, 1] and list(plan["success_step"]) == ["0", "1"]
        assert plan["episodes"] == 2 and plan["excluded_states"] == [] and "states" not in plan
        assert [plan["resets"][e]["seed"] for e in ("0", "1")] == [3000, 3001]
        assert all(len(plan["resets"][e]["offsets_m"]) == 7 for e in ("0", "1"))  # every movable object shifted
        assert plan["source_replay_step"] is None and plan["source_steps"] == 20  # the 20-step cap: no success
    entry = json.loads((out / blind_replay.REPORT_JSON).read_text())[SUITE][str(TASK_ID)]
    assert (entry["starts"], entry["resets_seed"], entry["placement_spread_cm"]) == ("resets", 3000, 3.0)
    assert entry["style"] == "scripted" and entry["reset_episodes"] == [0, 1]
    text = (out / blind_replay.REPORT_MD).read_text()
    assert "--seed=3000 --env.placement_spread_cm=3` (reset seeds 3000-3001)" in text
    assert "--resets-seed 3000 --episodes 2 --placement-spread-cm 3" in text


def test_reset_flags_are_checked_and_each_set_has_its_own_default_folder(tmp_path):
    for flags, message in [(["--episodes", "3"], "--episodes 3 needs --resets-seed"),
                           (["--placement-spread-cm", "3"], "--placement-spread-cm .* needs --resets-seed"),
                           (["--resets-seed", "3000", "--states", "1-3"], "pass one or the other"),
                           (["--resets-seed", "3000", "--episodes", "0"], "--episodes must be >= 1"),
                           (["--resets-seed", "3000", "--object-shift-cm", "4"], "use one or the other"),
                           (["--cross-task", "--resets-seed", "3000"], "--resets-seed .* not supported")]:
        with pytest.raises(SystemExit, match=message):
            predvla_main(["blind-replay", *flags, "--out", str(tmp_path)])
    official = blind_replay.task_path(tmp_path, SUITE, 3)
    atomic_write_json(official, {"settings": blind_replay.Settings().as_dict()})
    with pytest.raises(SystemExit, match="on other starts"):
        predvla_main(["blind-replay", "--suites", SUITE, "--tasks", "0", "--resets-seed", "3000", "--out",
                      str(tmp_path)])
    spec = blind_replay.ResetSpec
    assert blind_replay.default_folder("scripted", spec()) == blind_replay.DEFAULT_OUT
    assert str(blind_replay.default_folder("teleop", spec())) == "results/blind_replay_teleop"
    assert str(blind_replay.default_folder("scripted", spec(seed=3000))) == "results/blind_replay_resets3000"
    assert (str(blind_replay.default_folder("teleop", spec(seed=3000, placement_spread_cm=3.0)))
            == "results/blind_replay_resets3000_placed3cm_teleop")
