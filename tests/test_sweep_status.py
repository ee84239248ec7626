"""`predvla sweep --status`: each run's training, evaluation parts and successes so far, and the time left, read from
RUNS_DIR without running anything (fake executor)."""

import json

from sweep_factory import ClockRunsOut, FakeLeRobot, sweep_file

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.sweep import Run, Runner, Sweep
from lerobot_predvla.sweep.layout import EVAL_WALL_FILE
from lerobot_predvla.sweep.status import format_status, sweep_status


def test_status_follows_a_sweep_through_its_trainings_and_evaluation_parts(tmp_path, monkeypatch, capsys):
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"],
                      eval={"device": "cpu", "tasks": [0, 1, 2, 3], "n_episodes": 4})
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot())
    before = {row.key: row for row in sweep_status(runner, None, (0, 1))}
    assert list(before) == ["predvla/libero_object/seed0", "A6/libero_object/seed0", "L3/libero_object/seed0"]
    assert all((r.training, r.parts_done, r.parts, r.episodes) == ("not started", 0, 4, 0) for r in before.values())

    runner.execute = ClockRunsOut(runner)  # the first evaluation part finishes, then --stop-at passes
    assert runner.run(configs=["predvla"], progress=False)["stopped"]
    runner.stop_at, runner.execute = None, FakeLeRobot(kill_training=1)  # L3's training dies after a checkpoint
    assert runner.run(configs=["L3"], progress=False)["failed"] == ["L3/libero_object/seed0"]
    task0 = runner.eval_dir(Run("predvla", "libero_object", 0)) / "task0"
    (task0 / EVAL_WALL_FILE).write_text(json.dumps({"eval_wall_s": 600.0}))

    rows = {row.key: row for row in sweep_status(runner, None, (0, 1))}
    main = rows["predvla/libero_object/seed0"]
    assert (main.training, main.parts_done, main.successes, main.episodes, main.recorded) == ("done", 1, 4, 4, False)
    assert main.seconds_left(workers=1) == 1800 and main.seconds_left(workers=2) == 1200  # 3 parts of 600 s left
    assert rows["A6/libero_object/seed0"].training == "done" and rows["A6/libero_object/seed0"].seconds_left(2) is None
    assert rows["L3/libero_object/seed0"].training == "step 2 of 30,000"
    table = format_status(list(rows.values()), workers=2).splitlines()
    assert table[0].split() == ["run", "training", "evaluation", "parts", "successes", "left", "(est.)"]
    assert table[1].split() == ["predvla/libero_object/seed0", "done", "1/4", "4/4", "0.3", "h"]
    assert table[-1] == ("0 of 3 runs recorded; evaluation left about 0.3 h (not counting 2 runs with no timed part "
                         "yet) at 2 parts at once; trainings not counted")
    assert format_status(list(rows.values())[1:2], workers=1).splitlines()[-1] == (
        "0 of 1 runs recorded; evaluation left unknown (not counting 1 run with no timed part yet) at 1 part at once; "
        "trainings not counted")

    fake = FakeLeRobot()
    monkeypatch.setattr("lerobot_predvla.cli.sweep.Runner",
                        lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=fake, **kw))
    argv = ["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--status", "--configs", "predvla"]
    assert predvla_main(argv) == 0 and fake.commands == []
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 3 and out[1].split()[:4] == ["predvla/libero_object/seed0", "done", "1/4", "4/4"]
    assert runner.run(configs=["predvla"], progress=False)["done"] == ["predvla/libero_object/seed0"]
    recorded = sweep_status(runner, ["predvla"], (0, 1))[0]
    assert recorded.recorded and (recorded.parts_done, recorded.successes, recorded.episodes) == (4, 10, 16)
