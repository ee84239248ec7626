"""`predvla sweep --eval-tasks`: a run's record covers the tasks its calls evaluated, so a later call for other tasks
evaluates them and adds them to the record instead of skipping the run (fake lerobot-train / lerobot-eval)."""

import json
import signal

from sweep_factory import FakeLeRobot, arg, cli_flags, sweep_file

from lerobot_predvla.cli.sweep import apply_flags
from lerobot_predvla.sweep import Run, Runner, Sweep
from lerobot_predvla.sweep.layout import EVAL_WALL_FILE
from lerobot_predvla.sweep.workspace import describe_exit

RUN = Run("predvla", "libero_object", 0)


def runner_for(tmp_path, fake: FakeLeRobot, **flags) -> Runner:
    """The sweep of one run (4 episodes per task, tasks 0 and 1 by default) with `predvla sweep`'s flags applied."""
    sweep = Sweep.load(sweep_file(tmp_path, seeds=[0], suites=["libero_object"],
                                  eval={"device": "cpu", "tasks": [0, 1], "n_episodes": 4}))
    apply_flags(sweep, cli_flags(**flags))
    return Runner(sweep, tmp_path / "runs", execute=fake)


def evaluated_tasks(fake: FakeLeRobot) -> list[str | None]:
    return [arg(c, "env.task_ids") for c in fake.commands if any(x.endswith("lerobot-eval") for x in c)]


def test_a_later_call_for_other_tasks_evaluates_them_and_extends_the_record(tmp_path):
    first = FakeLeRobot()
    assert runner_for(tmp_path, first).run(configs=["predvla"], progress=False)["done"] == [RUN.key]
    runner = runner_for(tmp_path, FakeLeRobot())
    record = json.loads(runner.record_path(RUN).read_text())
    assert record["eval_tasks"] == [0, 1] and set(record["tasks"]) == {"0", "1"} and record["episodes"] == 8

    later = FakeLeRobot()
    runner = runner_for(tmp_path, later, eval_tasks=[2, 3])
    assert runner.pending_commands(["predvla"], (0, 1)) and runner.run(configs=["predvla"], progress=False) == {
        "done": [RUN.key], "skipped": [], "failed": [], "stopped": []}
    assert evaluated_tasks(later) == ["[2]", "[3]"] and later.count("lerobot-train") == 0
    record = json.loads(runner.record_path(RUN).read_text())
    assert record["eval_tasks"] == [0, 1, 2, 3]
    assert record["tasks"] == {"0": {"successes": 4, "episodes": 4}, "1": {"successes": 3, "episodes": 4},
                               "2": {"successes": 2, "episodes": 4}, "3": {"successes": 1, "episodes": 4}}
    assert record["successes"] == 10 and record["episodes"] == 16 and record["success_rate"] == 62.5
    assert [arg(c, "env.task_ids") for c in record["commands"]["eval"]] == ["[0]", "[1]", "[2]", "[3]"]

    # Tasks the record holds, in any combination: skipped, nothing run, the record unchanged.
    again = FakeLeRobot()
    runner = runner_for(tmp_path, again, eval_tasks=[1, 3])
    assert runner.pending_commands(["predvla"], (0, 1)) == []
    assert runner.run(configs=["predvla"], progress=False)["skipped"] == [RUN.key] and again.commands == []
    assert json.loads(runner.record_path(RUN).read_text()) == record

    # A call overlapping the record evaluates only the task it lacks; the shared task is kept, counted once.
    overlap = FakeLeRobot()
    runner = runner_for(tmp_path, overlap, eval_tasks=[3, 4])
    assert [arg(c, "env.task_ids") for c in runner.pending_commands(["predvla"], (0, 1))] == ["[4]"]
    assert runner.run(configs=["predvla"], progress=False)["done"] == [RUN.key]
    assert evaluated_tasks(overlap) == ["[4]"]
    extended = json.loads(runner.record_path(RUN).read_text())
    assert extended["eval_tasks"] == [0, 1, 2, 3, 4] and extended["episodes"] == 20
    assert len(extended["commands"]["eval"]) == 5


def test_the_record_names_the_machine_of_each_part_and_keeps_those_of_earlier_calls(tmp_path):
    """A run resumed on another machine: each part's file names where it ran, and the record keeps every part's."""
    runner_for(tmp_path, FakeLeRobot()).run(configs=["predvla"], progress=False)
    runner = runner_for(tmp_path, FakeLeRobot())
    first = json.loads(runner.record_path(RUN).read_text())["part_machines"]
    assert set(first) == {"0", "1"} and all("logical CPUs" in m and "; OpenBLAS " in m for m in first.values())
    part = tmp_path / "runs/eval/predvla/libero_object/seed0/task0" / EVAL_WALL_FILE
    assert json.loads(part.read_text())["machine"] == first["0"]
    record = json.loads(runner.record_path(RUN).read_text())
    record["part_machines"]["0"] = "elsewhere"
    runner.record_path(RUN).write_text(json.dumps(record))
    later = runner_for(tmp_path, FakeLeRobot(), eval_tasks=[4])
    later.run(configs=["predvla"], progress=False)
    machines = json.loads(later.record_path(RUN).read_text())["part_machines"]
    assert machines == {"0": "elsewhere", "1": first["1"], "4": first["1"]}


def test_tasks_of_another_protocol_do_not_join_a_record(tmp_path, capsys):
    """Other episodes per task than the record's: the run fails before evaluating, naming the field, and the record
    keeps its tasks."""
    runner_for(tmp_path, FakeLeRobot()).run(configs=["predvla"], progress=False)
    runner = runner_for(tmp_path, FakeLeRobot(), eval_tasks=[2], n_episodes=6)
    before = runner.record_path(RUN).read_text()
    assert runner.run(configs=["predvla"], progress=False)["failed"] == [RUN.key]
    assert evaluated_tasks(runner.execute) == []
    err = capsys.readouterr().err
    assert "n_episodes_per_task = 4" in err and "n_episodes_per_task = 6" in err and str(runner.record_path(RUN)) in err
    assert runner.record_path(RUN).read_text() == before


def test_a_whole_suite_call_evaluates_a_run_recorded_task_by_task(tmp_path):
    """Without `eval.tasks` a call evaluates the whole suite at once: a record of some tasks does not hold it."""
    runner_for(tmp_path, FakeLeRobot()).run(configs=["predvla"], progress=False)
    whole = FakeLeRobot()
    runner = runner_for(tmp_path, whole)
    runner.sweep.settings.eval_tasks = None
    assert runner.run(configs=["predvla"], progress=False)["done"] == [RUN.key]
    assert evaluated_tasks(whole) == [None]
    record = json.loads(runner.record_path(RUN).read_text())
    assert record["eval_tasks"] is None and set(record["tasks"]) == {"0", "1", "2"}
    again = FakeLeRobot()
    runner.execute = again
    assert runner.run(configs=["predvla"], progress=False)["skipped"] == [RUN.key] and again.commands == []


class IllegalInstruction(FakeLeRobot):
    """A FakeLeRobot whose lerobot-eval dies on an illegal instruction (as under kernels the processor lacks)."""

    def __call__(self, command: list[str], log) -> int:
        if any(c.endswith("lerobot-eval") for c in command):
            self.commands.append(command)
            return -signal.SIGILL
        return super().__call__(command, log)


def test_an_evaluation_ended_by_a_signal_is_reported_with_its_name_and_usual_cause(tmp_path, capsys):
    runner = runner_for(tmp_path, IllegalInstruction())
    assert runner.run(configs=["predvla"], progress=False)["failed"] == [RUN.key]
    err = capsys.readouterr().err
    assert "failed (killed by SIGILL: an instruction this processor lacks" in err and "OPENBLAS_CORETYPE" in err


def test_exit_codes_in_words():
    assert describe_exit(2) == "exit 2"
    assert describe_exit(-signal.SIGKILL).startswith("killed by SIGKILL: killed from outside")
    assert describe_exit(-signal.SIGTERM) == "killed by SIGTERM"
    assert describe_exit(-999) == "exit -999"
