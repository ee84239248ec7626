"""`python -m research.demonstration_sets`: one dataset's screen per evaluation set, against its blind replays, on
hand-made run records and blind-replay reports."""

import json
import shutil

from research import demonstration_sets as ds


def write_record(runs, config: str, successes: int, episodes: int = 30) -> None:
    path = runs / "records" / config / "libero_object" / "seed0.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps({"config": config, "successes": successes, "episodes": episodes}))


def write_blind(blind, folder: str, tasks: dict) -> None:
    """A blind-replay report.json of these tasks' state-0 plans (the nearest-mean plan's numbers set alike)."""
    (blind / folder).mkdir(parents=True)
    tasks = {k: {**t, "nearest_mean_plan": {"successes": 0, "episodes": t["episodes"]}} for k, t in tasks.items()}
    (blind / folder / "report.json").write_text(json.dumps({"libero_object": tasks}))


def test_cells_per_set_with_the_blind_replay_on_the_same_starts(tmp_path, capsys):
    runs, blind, out = tmp_path / "runs", tmp_path / "blind", tmp_path / "out"
    write_record(runs, "olt_open_loop", 10)  # E1
    write_record(runs, "olt_shifted", 2)  # E3, Table 2's error regression
    write_record(runs, "B1_placed_resets", 16)  # E2p
    write_record(runs, "olt_open_loop_carried", 30)  # no such policy: ignored
    # E1: the plan on states 1-9 of two tasks plus its replay on its own start (state 0) of each
    write_blind(blind, "E1_teleop", {"2": {"successes": 8, "episodes": 9, "source_replay_success": True},
                                     "3": {"successes": 5, "episodes": 9, "source_replay_success": False}})
    write_blind(blind, "E3_teleop", {"2": {"successes": 1, "episodes": 10, "source_replay_success": True}})
    write_blind(blind, "E3_scripted", {"2": {"successes": 9, "episodes": 10, "source_replay_success": True}})
    assert ds.main(["--runs", str(runs), "--blind", str(blind), "--style", "teleop", "--out", str(out)]) == 0
    report = json.loads((out / "sets.json").read_text())
    cells = report["cells"]
    assert cells["PredVLA fit_sensory_olt, exact open loop"] == {"E1": [10, 30], "E2": None, "E2p": None, "E3": None}
    assert cells["PredVLA fit_sensory_olt, Table 2's error regression"]["E3"] == [2, 30]
    assert cells["BC-Transformer (B1)"]["E2p"] == [16, 30]
    assert report["blind_replay"] == {"E1": [14, 20], "E2": None, "E2p": None, "E3": [1, 10]}
    md = (out / "sets.md").read_text()
    assert "| PredVLA fit_sensory_olt, exact open loop | 33.3 (10/30) | not run | not run | not run |" in md
    assert "one teleop demonstration replayed blind (plan from official init state 0) | 70.0 (14/20) |" in md
    assert (out / "sets.png").stat().st_size > 0


def test_a_broken_record_is_named(tmp_path, capsys):
    runs = tmp_path / "runs"
    path = runs / "records" / "B2" / "libero_object" / "seed0.json"
    path.parent.mkdir(parents=True)
    path.write_text("{}")
    args = ["--runs", str(runs), "--blind", str(tmp_path), "--style", "scripted", "--out", str(tmp_path / "o")]
    assert ds.main(args) == 2
    assert f"{path}: not a run record" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    assert ds.main([*args[:1], str(tmp_path / "none"), *args[2:]]) == 2
    assert "no records/ folder" in capsys.readouterr().err


def test_apart_splits_every_cell_and_blind_figure_into_the_listed_tasks_and_the_others(tmp_path, capsys):
    """Full scale: the screen's tasks (listed) apart from the unscreened ones, from the per-task counts."""
    runs, blind, out = tmp_path / "runs", tmp_path / "blind", tmp_path / "out"
    per_task = {"0": 20, "2": 5, "3": 1, "9": 12}  # successes of 20 episodes per task
    write_record(runs, "olt_open_loop_shifted", sum(per_task.values()), 80)
    record = runs / "records" / "olt_open_loop_shifted" / "libero_object" / "seed0.json"
    record.write_text(json.dumps({**json.loads(record.read_text()),
                                  "tasks": {t: {"successes": s, "episodes": 20} for t, s in per_task.items()}}))
    write_blind(blind, "E3_teleop", {t: {"successes": s, "episodes": 20, "source_replay_success": False}
                                     for t, s in {"0": 3, "2": 1, "3": 0, "9": 6}.items()})
    write_blind(blind, "E1_teleop", {t: {"successes": 19, "episodes": 19, "source_replay_success": t != "3"}
                                     for t in ("0", "2", "3", "9")})
    args = ["--runs", str(runs), "--blind", str(blind), "--style", "teleop", "--out", str(out)]
    assert ds.main([*args, "--apart", "2,3"]) == 0
    report = json.loads((out / "sets.json").read_text())
    apart = report["apart"]
    assert apart["tasks"] == [2, 3]
    assert apart["cells"]["PredVLA fit_sensory_olt, exact open loop"]["E3"] == {"listed": [6, 40],
                                                                                "others": [32, 40]}
    assert apart["cells"]["PredVLA fit_sensory_olt, exact open loop"]["E1"] is None
    assert report["cells"]["PredVLA fit_sensory_olt, exact open loop"]["E3"] == [38, 80]
    assert apart["blind_replay"]["E3"] == {"listed": [1, 40], "others": [9, 40]}
    assert apart["blind_replay"]["E1"] == {"listed": [39, 40], "others": [40, 40]}  # own start: not on task 3
    md = (out / "sets.md").read_text()
    assert "The same cells on tasks 2, 3 / on the other tasks:" in md
    assert "| 15.0 (6/40) / 80.0 (32/40) |" in md
    # A record without per-task counts cannot be split, and says so.
    write_record(runs, "B1_shifted", 3)
    capsys.readouterr()
    assert ds.main([*args, "--apart", "2,3"]) == 2
    assert "B1_shifted/libero_object/seed0.json: no per-task counts" in capsys.readouterr().err
    assert ds.main(args) == 0 and "apart" not in json.loads((out / "sets.json").read_text())


def test_successes_on_starts_where_the_blind_replay_succeeds_too_beside_chance(tmp_path, capsys):
    """Per cell and set, from the cell's episodes and the blind replay's per-start outcomes: on E3, 3 successes of
    which 2 on starts where the blind plan succeeds (2 of 4 starts: chance 1.5); on E1 the plan's own start counts."""
    runs, blind, out = tmp_path / "runs", tmp_path / "blind", tmp_path / "out"
    cells = {"olt_carried_shifted": {2: [True, True, False, True]}, "olt_carried": {2: [True, False, False, False]}}
    for config, tasks in cells.items():
        write_record(runs, config, sum(map(sum, tasks.values())), 4)
        part = runs / "eval" / config / "libero_object" / "seed0" / "task2"
        part.mkdir(parents=True)
        part.joinpath("eval_info.json").write_text(json.dumps({"per_task": [
            {"task_group": "libero_object", "task_id": t, "metrics": {"successes": s}} for t, s in tasks.items()]}))
    for folder, steps, source_step in (("E3_teleop", {"0": 150, "1": 151, "2": None, "3": None}, None),
                                       ("E1_teleop", {"1": None, "2": None, "3": None}, 149)):
        write_blind(blind, folder, {"2": {"successes": sum(v is not None for v in steps.values()),
                                          "episodes": len(steps), "source_replay_success": True}})
        path = blind / folder / "tasks" / "libero_object" / "task2.json"
        path.parent.mkdir(parents=True)
        path.write_text(json.dumps({"task_id": 2, "plans": {"state0": {
            "success_step": steps, "source_state": 0, "source_replay_step": source_step}}}))
    assert ds.main(["--runs", str(runs), "--blind", str(blind), "--style", "teleop", "--out", str(out)]) == 0
    overlap = json.loads((out / "sets.json").read_text())["blind_overlap"]
    label = "PredVLA fit_sensory_olt, error regression, Adam carried"
    assert overlap[label]["E3"] == {"starts": 4, "successes": 3, "with_blind": 2, "by_chance": 1.5}
    assert overlap[label]["E1"] == {"starts": 4, "successes": 1, "with_blind": 1, "by_chance": 0.25}
    assert "| 1 of 1 (by chance 0.2) | - | - | 2 of 3 (by chance 1.5) |" in (out / "sets.md").read_text()

    # Episodes without per-start blind outcomes give no overlap table; a per-task file without them is named.
    shutil.rmtree(runs / "eval")
    assert ds.main(["--runs", str(runs), "--blind", str(blind), "--style", "teleop", "--out", str(out)]) == 0
    assert "blind_overlap" not in json.loads((out / "sets.json").read_text())
    path = blind / "E3_teleop" / "tasks" / "libero_object" / "task2.json"
    path.write_text(json.dumps({"task_id": 2, "plans": {"state0": {}}}))
    assert ds.main(["--runs", str(runs), "--blind", str(blind), "--style", "teleop", "--out", str(out)]) == 2
    assert f"{path}: no per-start outcomes of the state-0 plan" in capsys.readouterr().err
