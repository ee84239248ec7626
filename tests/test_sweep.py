"""`predvla sweep`: run records, skipping, resuming, sharding, data stages, evaluation workers and commands (fake
executor)."""

import json
import os
import shutil
import time
from pathlib import Path

import pytest
import torch
import yaml
from safetensors.torch import save_file
from sweep_factory import ClockRunsOut, FakeData, FakeLeRobot, arg, cli_flags, sweep_file

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.report import write_report
from lerobot_predvla.sweep import (
    TRAIN_DONE_FILE,
    Run,
    Runner,
    Sweep,
    SweepError,
    parse_shard,
)
from lerobot_predvla.sweep.eval_info import EvalInfoError, parse_eval_info
from lerobot_predvla.utils.manifest import sha256_file
from lerobot_predvla.utils.versions import machine, openblas_coretype


def test_runs_write_records_and_inference_variants_reuse_checkpoints(tmp_path):
    fake = FakeLeRobot()
    runner = Runner(Sweep.load(sweep_file(tmp_path)), tmp_path / "runs", execute=fake)
    outcome = runner.run(progress=False)
    # predvla and A6: 2 suites x 2 seeds; L3: 1 suite x 2 seeds.
    assert len(outcome["done"]) == 10 and not outcome["failed"]
    assert fake.count("lerobot-train") == 6 and fake.count("lerobot-eval") == 10  # A6 trains nothing
    record = json.loads((tmp_path / "runs/records/A6/libero_object/seed1.json").read_text())
    assert record["tasks"] == {"0": {"successes": 49, "episodes": 50}, "1": {"successes": 48, "episodes": 50},
                               "2": {"successes": 47, "episodes": 50}}
    assert record["success_rate"] == pytest.approx(100 * 144 / 150)
    assert record["parameters"] == 17 and record["steps"] == 30_000 and record["group"] == "ablation"
    assert record["checkpoint"].endswith("train/predvla/libero_object/seed1/checkpoints/000002/pretrained_model")
    assert {"lerobot", "torch", "python", "machine", "openblas_coretype"} <= set(record["versions"])
    assert record["versions"]["omp_num_threads"] == os.environ.get("OMP_NUM_THREADS", "unset")
    a6_eval = record["commands"]["eval"]
    assert "--policy.er_iterations=0" in a6_eval and "--env.episode_length=600" in a6_eval
    assert "--eval.n_episodes=50" in a6_eval and "--env.init_states=true" in a6_eval
    assert "--env.type=predvla_libero" in a6_eval and "--env.task=libero_object" in a6_eval
    l3_train = next(c for c in fake.commands if arg(c, "job_name") == "L3_libero_object_seed0")
    assert "--policy.type=predvla" in l3_train and "--policy.tau=[1,1,1,1]" in l3_train
    assert "--policy.er_iterations=0" in l3_train and "--steps=30000" in l3_train and "--batch_size=32" in l3_train
    assert arg(l3_train, "dataset.root") == str(tmp_path / "data" / "libero_object")
    plan = json.loads((tmp_path / "runs/plan.json").read_text())
    assert len(plan["runs"]) == 10 and plan["configs"]["A6"]["checkpoint_from"] == "predvla"

    again = FakeLeRobot()
    runner.execute = again
    outcome = runner.run(progress=False)
    assert len(outcome["skipped"]) == 10 and again.commands == []

    summary = write_report(tmp_path / "runs", tmp_path / "report")  # the records feed the report as written
    paired = summary["configs"]["A6"]["paired"]["libero_object"]
    assert paired["n"] == 2 and paired["delta"] == 0.0 and summary["missing_runs"] == []


def test_killed_training_resumes_and_killed_eval_is_redone(tmp_path):
    sweep = Sweep.load(sweep_file(tmp_path, seeds=[0], suites=["libero_object"]))
    fake = FakeLeRobot(kill_training=1)
    runner = Runner(sweep, tmp_path / "runs", execute=fake)
    outcome = runner.run(configs=["predvla"], progress=False)
    assert outcome["failed"] == ["predvla/libero_object/seed0"]
    assert not runner.record_path(Run("predvla", "libero_object", 0)).exists()

    runner.eval_dir(Run("predvla", "libero_object", 0)).mkdir(parents=True)  # an evaluation killed midway
    outcome = runner.run(configs=["predvla"], progress=False)
    assert outcome["done"] == ["predvla/libero_object/seed0"]
    resume = fake.commands[1]
    assert "--resume=true" in resume
    assert arg(resume, "config_path").endswith("seed0/checkpoints/last/pretrained_model/train_config.json")
    trained = json.loads((runner.train_dir("predvla", "libero_object", 0) / TRAIN_DONE_FILE).read_text())
    assert trained["resumed"] and trained["machine"] == machine()


def test_a_later_call_with_other_seeds_adds_to_the_plan(tmp_path):
    """`--configs predvla --seeds 1` after a seed-0 sweep plans predvla's seed 1 beside seed 0, so the report
    still knows both, and no other configuration at seed 1: that call runs none."""
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"])
    Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot()).run(progress=False)
    later = Sweep.load(path)
    later.settings.seeds = [1]  # what `predvla sweep --seeds 1` does
    Runner(later, tmp_path / "runs", execute=FakeLeRobot()).run(configs=["predvla"], progress=False)
    plan = json.loads((tmp_path / "runs/plan.json").read_text())
    assert sorted((r["config"], r["seed"]) for r in plan["runs"]) == [
        ("A6", 0), ("L3", 0), ("predvla", 0), ("predvla", 1)]
    summary = write_report(tmp_path / "runs", tmp_path / "report")
    assert summary["missing_runs"] == []

    (tmp_path / "runs/plan.json").write_text("{not json")
    with pytest.raises(SweepError, match="plan.json"):
        Runner(later, tmp_path / "runs", execute=FakeLeRobot()).run(progress=False)


def test_a_restricted_call_with_fewer_episodes_keeps_the_other_configurations_protocol(tmp_path):
    """`--configs L3 --n-episodes 3` after a full sweep: A6 keeps its 5 episodes in the plan, and so does the
    sweep-wide protocol; only L3's description is written afresh."""
    from lerobot_predvla.cli.sweep import apply_flags

    configs = yaml.safe_load(sweep_file(tmp_path).read_text())["configs"]
    configs[1]["n_episodes"] = 5
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], configs=configs)
    Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot()).run(progress=False)
    before = json.loads((tmp_path / "runs/plan.json").read_text())
    assert before["configs"]["A6"]["n_episodes"] == 5

    later = Sweep.load(path)
    apply_flags(later, cli_flags(n_episodes=3))
    fake = FakeLeRobot()
    Runner(later, tmp_path / "runs", execute=fake).run(configs=["L3"], progress=False)
    assert fake.commands == []  # L3 was already evaluated: nothing reruns
    after = json.loads((tmp_path / "runs/plan.json").read_text())
    assert after["configs"]["A6"] == before["configs"]["A6"] and after["protocol"] == before["protocol"]
    assert after["configs"]["L3"]["n_episodes"] is None and after["runs"] == before["runs"]


def test_seeds_flag_keeps_a_configurations_own_seeds_only_where_they_overlap(tmp_path):
    """A configuration that names its own seeds (the Table 2 sweep's seeds 1-2 evaluations) is not run at a seed
    `--seeds` asks for but it does not name; the others take `--seeds` as it is."""
    from lerobot_predvla.cli.sweep import apply_flags

    configs = yaml.safe_load(sweep_file(tmp_path).read_text())["configs"]
    configs[1]["seeds"] = [1, 2]
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], configs=configs)
    name = configs[1]["name"]
    for seeds, own in (([0], []), ([1, 3], [1]), (None, [1, 2])):
        sweep = Sweep.load(path)
        apply_flags(sweep, cli_flags(seeds=seeds))
        sweep.validate(path)  # as `predvla sweep` does after the flags: a configuration left no seeds is valid
        runs = sweep.runs()
        assert sorted(r.seed for r in runs if r.config == name) == own
        assert sorted(r.seed for r in runs if r.config == "predvla") == (seeds or [0])

    Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot()).run(configs=[name], progress=False)
    later = Sweep.load(path)
    apply_flags(later, cli_flags(seeds=[1]))  # a later call for one of its seeds: the plan still names both
    Runner(later, tmp_path / "runs", execute=FakeLeRobot()).run(configs=[name], progress=False)
    assert json.loads((tmp_path / "runs/plan.json").read_text())["configs"][name]["seeds"] == [1, 2]


def test_suites_flag_keeps_a_configurations_own_suites_only_where_they_overlap(tmp_path):
    """L3 names only libero_object: `--suites libero_spatial` runs it nowhere rather than on a suite it never named;
    the configurations without their own suites take `--suites` as it is."""
    from lerobot_predvla.cli.sweep import apply_flags

    both = ["libero_object", "libero_spatial"]
    for suites, own in ((["libero_spatial"], []), (both, ["libero_object"]), (None, ["libero_object"])):
        sweep = Sweep.load(sweep_file(tmp_path))
        apply_flags(sweep, cli_flags(suites=suites))
        sweep.validate(tmp_path / "sweep.yaml")
        runs = sweep.runs()
        assert sorted({r.suite for r in runs if r.config == "L3"}) == own
        assert sorted({r.suite for r in runs if r.config == "predvla"}) == (suites or both)
    configs = yaml.safe_load(sweep_file(tmp_path).read_text())["configs"]
    configs[2]["suites"] = []
    with pytest.raises(SweepError, match="configuration L3: `suites` is empty"):
        Sweep.load(sweep_file(tmp_path, configs=configs))


def test_shards_partition_training_units(tmp_path):
    sweep = Sweep.load(sweep_file(tmp_path))
    shards = [Runner(sweep, tmp_path / "runs").shard_units(None, (i, 3)) for i in range(3)]
    keys = [[r.key for _, runs in units for r in runs] for units in shards]
    assert sorted(k for ks in keys for k in ks) == sorted(r.key for r in sweep.runs())
    assert all(ks for ks in keys)
    for units in shards:  # an inference-time variant runs where its checkpoint is trained
        for (trained, suite, seed), runs in units:
            assert {r.config for r in runs} <= {trained, "A6"}
            assert all((r.suite, r.seed) == (suite, seed) for r in runs)
    assert parse_shard("2/3") == (2, 3)
    for bad in ("3/3", "x", "1/0"):
        with pytest.raises(SweepError, match="--shard"):
            parse_shard(bad)


def test_flags_shrink_the_protocol_and_accelerate_launch(tmp_path, capsys):
    path = sweep_file(tmp_path)
    code = predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--dry-run", "--configs", "A6",
                         "--steps", "5", "--n-episodes", "2", "--episode-length", "100", "--seeds", "3",
                         "--suites", "libero_object", "--accelerate-processes", "2", "--device", "cuda"])
    assert code == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2  # train predvla (the checkpoint A6 needs), evaluate A6
    train, evaluate = lines
    assert " launch --multi_gpu --num_processes=2 " in train and "--batch_size=16" in train and "--steps=5" in train
    assert "--seed=3" in train and "libero_object" in train
    assert "--eval.n_episodes=2" in evaluate and "--env.episode_length=100" in evaluate
    code = predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--dry-run", "--configs", "A6",
                         "--suites", "libero_object", "--seeds", "3", "--accelerate-processes", "2", "--device", "cpu"])
    train = capsys.readouterr().out.strip().splitlines()[0]
    assert "torchrun --nproc_per_node=2 " in train and "--policy.device=cpu" in train  # DDP on CPU: torchrun
    assert not (tmp_path / "runs" / "records").exists()


def test_bad_sweep_files_name_the_problem(tmp_path, capsys):
    cases = [
        ({"configs": [{"name": "x", "group": "other"}]}, "group 'other'"),
        ({"configs": [{"name": "x", "checkpoint_from": "y"}]}, "unknown configuration 'y'"),
        ({"datasets": {}}, "`datasets` has no entry"),
        ({"configs": [{"name": "x", "nonsense": 1}]}, "nonsense"),
        ({"configs": [{"name": "x", "paper": {"libero_objects": 89.2}}]}, "`paper` maps a suite"),
        ({"configs": [{"name": "x", "paper": {"libero_object": [89.2, 6.1, 3]}}]}, "`paper` maps a suite"),
        ({"configs": [{"name": "x", "seeds": []}]}, "`seeds` is empty"),
    ]
    for changes, message in cases:
        path = sweep_file(tmp_path, **changes)
        assert predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "r"), "--dry-run"]) == 2
        err = capsys.readouterr().err
        assert message in err and str(path) in err


def test_extends_takes_every_setting_but_the_configurations_from_a_file_in_the_same_folder(tmp_path, capsys):
    base = sweep_file(tmp_path, seeds=[3], train={"device": "cpu", "steps": 77}, eval={"device": "cpu", "tasks": [2]})
    second = tmp_path / "second.yaml"
    second.write_text(yaml.safe_dump({"extends": base.name, "configs": [{"name": "fast", "group": "main"}]}))
    sweep = Sweep.load(second)
    assert list(sweep.configs) == ["fast"] and sweep.settings == Sweep.load(base).settings
    assert sweep.settings.seeds == [3] and sweep.settings.steps == 77 and sweep.settings.eval_tasks == [2]
    assert sweep.base_dir == base.parent  # the base file's relative paths mean the same in the second file

    (tmp_path / "sub").mkdir()
    cases = [
        ({"extends": "sub/../sweep.yaml"}, "must name a sweep file in the same folder"),
        ({"extends": "missing.yaml"}, "missing.yaml not found"),
        ({"extends": base.name, "seeds": [0]}, "remove its own keys ['seeds']"),
        ({"extends": "third.yaml"}, "extends another file itself"),
    ]
    (tmp_path / "third.yaml").write_text(yaml.safe_dump({"extends": base.name, "configs": [{"name": "y"}]}))
    for changes, message in cases:
        second.write_text(yaml.safe_dump({**changes, "configs": [{"name": "fast", "group": "main"}]}))
        assert predvla_main(["sweep", str(second), "--runs-dir", str(tmp_path / "r"), "--dry-run"]) == 2
        err = capsys.readouterr().err
        assert message in err and str(second) in err


def test_parse_eval_info_reads_lerobot_eval_output(tmp_path):
    path = tmp_path / "eval_info.json"
    path.write_text(json.dumps({"per_task": [
        {"task_group": "libero_object", "task_id": 1, "metrics": {"successes": [True, False, True]}},
        {"task_group": "libero_object", "task_id": 0, "metrics": {"successes": [False, False, False]}},
    ], "per_group": {}, "overall": {}}))
    assert parse_eval_info(path) == {"0": {"successes": 0, "episodes": 3}, "1": {"successes": 2, "episodes": 3}}
    path.write_text(json.dumps({"overall": {}}))
    with pytest.raises(EvalInfoError, match="eval_info.json"):
        parse_eval_info(path)


def test_data_stages_and_task_by_task_evaluation_resume(tmp_path):
    """`data` makes the dataset (demonstrations task by task, front end, conversion), each stage skipped once its
    output exists; `eval.tasks` evaluates task by task and keeps the finished tasks of a killed evaluation."""
    data = {"libero_object": {"hdf5": "out/hdf5", "frontend": "out/frontend", "per_task": 3, "tasks": [0, 1],
                              "vision_weights": "random"}}
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], data=data,
                      eval={"device": "cpu", "tasks": [0, 1], "n_episodes": 4})
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeData())
    from lerobot_predvla.sims.libero.env import task_spec
    from lerobot_predvla.sims.libero.hdf5_layout import task_file

    done_task = task_file(tmp_path / "out/hdf5", task_spec("libero_object", 1))  # a killed demos run left task 1
    done_task.parent.mkdir(parents=True)
    done_task.write_text("demos")
    stages = [c[c.index("lerobot_predvla.cli.main") + 1:] for c in runner.pending_commands(["predvla"], (0, 1))[:3]]
    assert [s[0] for s in stages] == ["demos", "fit-frontend", "convert"]
    assert stages[0][stages[0].index("--tasks") + 1] == "0" and "--language-from" in stages[1]
    # Evaluation of task 0 finished before the run was killed: only task 1 is evaluated again.
    task0 = runner.eval_dir(Run("predvla", "libero_object", 0)) / "task0"
    task0.mkdir(parents=True)
    (task0 / "eval_info.json").write_text(json.dumps({"per_task": [
        {"task_id": 0, "metrics": {"successes": [True, True, False, True]}}]}))
    outcome = runner.run(configs=["predvla"], progress=False)
    assert outcome["done"] == ["predvla/libero_object/seed0"]
    evals = [c for c in runner.execute.commands if any(x.endswith("lerobot-eval") for x in c)]
    assert len(evals) == 1 and "--env.task_ids=[1]" in evals[0] and arg(evals[0], "output_dir").endswith("task1")
    record = json.loads(runner.record_path(Run("predvla", "libero_object", 0)).read_text())
    assert record["tasks"]["0"] == {"successes": 3, "episodes": 4} and record["episodes"] == 8
    assert (tmp_path / "data/libero_object/meta/info.json").is_file()
    assert runner.data_commands("libero_object") == []  # the dataset exists: nothing to make
    stages = json.loads((tmp_path / "runs/data/libero_object.json").read_text())
    assert list(stages) == ["demos", "frontend", "convert"] and stages["convert"]["wall_s"] >= 0
    assert stages["demos"]["openblas_coretype"] == openblas_coretype()
    # On another machine with the finished training but no dataset, evaluating makes no data.
    import shutil

    shutil.rmtree(tmp_path / "data")
    shutil.rmtree(runner.eval_dir(Run("predvla", "libero_object", 0)))
    runner.record_path(Run("predvla", "libero_object", 0)).unlink()
    runner.execute = FakeData()
    assert runner.run(configs=["predvla"], progress=False)["done"] == ["predvla/libero_object/seed0"]
    assert all("lerobot_predvla.cli.main" not in c for c in runner.execute.commands)


def test_demonstrations_split_across_data_workers(tmp_path):
    """`data.workers: 2` runs two `predvla demos` processes at once, each on every other missing task with its own
    log; a failed share is reported and only its tasks run again; a bad value is refused."""
    import threading

    class TwoAtOnce(FakeData):
        def __init__(self, fail: str | None = None):
            super().__init__()
            self.barrier, self.fail = threading.Barrier(2, timeout=10), fail

        def __call__(self, command: list[str], log: Path) -> int:
            if "demos" in command:
                self.barrier.wait()  # raises unless both shares run at the same time
                log.parent.mkdir(parents=True, exist_ok=True)
                log.write_text("demos")
                if command[command.index("--tasks") + 1] == self.fail:
                    self.commands.append(command)
                    return 1
            return super().__call__(command, log)

    data = {"libero_object": {"hdf5": "out/hdf5", "frontend": "out/frontend", "per_task": 3, "tasks": [0, 1, 2, 3],
                              "vision_weights": "random", "workers": 2}}
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], data=data)
    from lerobot_predvla.sims.libero.env import task_spec
    from lerobot_predvla.sims.libero.hdf5_layout import task_file

    done_task = task_file(tmp_path / "out/hdf5", task_spec("libero_object", 1))
    done_task.parent.mkdir(parents=True)
    done_task.write_text("demos")
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=TwoAtOnce(fail="2"))
    assert [stage for stage, _ in runner.data_commands("libero_object")][:2] == ["demos.tasks0", "demos.tasks1"]
    assert not runner.make_data("libero_object")  # the share of tasks 2 failed: no front end is fitted
    shares = [c[c.index("--tasks") + 1] for c in runner.execute.commands]
    assert sorted(shares) == ["0,3", "2"]
    assert list(json.loads((tmp_path / "runs/data/libero_object.json").read_text())) == ["demos.tasks0"]
    assert (tmp_path / "runs/logs/data/libero_object/seed0.demos.tasks1.log").is_file()
    (stage, command), *_ = runner.data_commands("libero_object")  # one task left: one process, one log
    assert stage == "demos" and command[command.index("--tasks") + 1] == "2"
    runner.execute = FakeData()
    assert runner.make_data("libero_object") and runner.data_commands("libero_object") == []
    bad = yaml.safe_load(path.read_text())
    bad["data"]["libero_object"]["workers"] = 0
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(SweepError, match="data.libero_object.workers must be >= 1"):
        Sweep.load(path)


def test_evaluation_parts_run_in_parallel_workers_with_their_own_logs(tmp_path):
    """`eval.workers: 2` runs two task parts at once (one lerobot-eval each, e.g. one per CPU core), each part
    logging to its own file; the record is the same as one worker's, and a bad value is refused."""
    import threading

    class Concurrent(FakeLeRobot):
        def __init__(self):
            super().__init__()
            self.running, self.most, self.lock, self.logs = 0, 0, threading.Lock(), []

        def __call__(self, command: list[str], log: Path) -> int:
            if not any(c.endswith("lerobot-eval") for c in command):
                return super().__call__(command, log)
            with self.lock:
                self.running += 1
                self.most = max(self.most, self.running)
                self.logs.append(log.name)
            time.sleep(0.05)
            code = super().__call__(command, log)
            with self.lock:
                self.running -= 1
            return code

    records = {}
    for workers in (1, 2):
        (tmp_path / str(workers)).mkdir()
        path = sweep_file(tmp_path / str(workers), seeds=[0], suites=["libero_object"],
                          eval={"device": "cpu", "tasks": [0, 1, 2, 3], "n_episodes": 4, "workers": workers})
        runner = Runner(Sweep.load(path), tmp_path / str(workers) / "runs", execute=Concurrent())
        assert runner.run(configs=["predvla"], progress=False)["done"] == ["predvla/libero_object/seed0"]
        record = json.loads(runner.record_path(Run("predvla", "libero_object", 0)).read_text())
        records[workers] = record
        assert runner.execute.most == workers
        expected = {"seed0.eval.log"} if workers == 1 else {f"seed0.eval.task{t}.log" for t in range(4)}
        assert set(runner.execute.logs) == expected
    assert records[1]["tasks"] == records[2]["tasks"] and records[2]["eval_workers"] == 2
    (tmp_path / "bad").mkdir()
    bad = sweep_file(tmp_path / "bad", eval={"device": "cpu", "workers": 0})
    with pytest.raises(SweepError, match="eval.workers must be >= 1"):
        Sweep.load(bad)


def test_stop_at_starts_nothing_after_its_time_and_the_same_call_resumes(tmp_path, monkeypatch, capsys):
    """`--stop-at`: a part running when the time passes finishes, no later one starts and the unfinished run gets no
    record; the same call later evaluates only the parts left. Past it, nothing starts at all (not even the
    training); a time that is not one is named."""
    from datetime import UTC, datetime, timedelta

    from lerobot_predvla.cli import sweep as sweep_cli

    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"],
                      eval={"device": "cpu", "tasks": [0, 1, 2, 3], "n_episodes": 4})
    past = datetime.now(UTC) - timedelta(minutes=1)
    run = Run("predvla", "libero_object", 0)
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot(), stop_at=past)
    outcome = runner.run(configs=["predvla"], progress=False)
    assert runner.execute.commands == [] and outcome["done"] == outcome["failed"] == []
    assert outcome["stopped"] == [f"training {run.key} not started: --stop-at {past.isoformat(timespec='minutes')} "
                                  "passed"]

    runner.stop_at, runner.execute = None, ClockRunsOut(runner)  # the time passes while the first part runs
    outcome = runner.run(configs=["predvla"], progress=False)
    assert runner.execute.count("lerobot-train") == 1 and runner.execute.count("lerobot-eval") == 1
    assert outcome["done"] == [] and outcome["stopped"][0].startswith(f"evaluation {run.key} (task1) not started")
    assert not runner.record_path(run).exists()
    runner.stop_at, runner.execute = None, FakeLeRobot()
    assert runner.run(configs=["predvla"], progress=False)["done"] == [run.key]
    assert [arg(c, "env.task_ids") for c in runner.execute.commands] == ["[1]", "[2]", "[3]"]
    assert sorted(json.loads(runner.record_path(run).read_text())["tasks"]) == ["0", "1", "2", "3"]

    fake = FakeLeRobot()
    monkeypatch.setattr(sweep_cli, "Runner", lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=fake, **kw))
    argv = ["sweep", str(path), "--runs-dir", str(tmp_path / "runs2")]
    assert predvla_main([*argv, "--stop-at", past.isoformat()]) == 0 and fake.commands == []
    assert "predvla sweep: stopped, training predvla/libero_object/seed0 not started" in capsys.readouterr().err
    for bad in ("25:00", "tomorrow"):
        with pytest.raises(SystemExit):
            predvla_main([*argv, "--stop-at", bad])
        assert "--stop-at: expected HH:MM or an ISO 8601 date and time" in capsys.readouterr().err
    at = sweep_cli.stop_time("00:00")  # the next midnight, local time
    assert timedelta(0) < at - datetime.now().astimezone() <= timedelta(days=1) and (at.hour, at.minute) == (0, 0)


def test_pool_with_names_a_pool_whose_paired_episodes_pool_too(tmp_path):
    """Seeds 1-2 of error regression and open loop pool with seed 0's: accepted; a pool whose comparisons would
    not pool, a chain of pools or an unknown name is refused, naming the configuration."""
    open_loop = {"er_iterations": 0}
    er = {"name": "predvla"}
    ol = {"name": "A6", "checkpoint_from": "predvla", "compare_to": "predvla", "eval_overrides": open_loop}
    er_seeds = {"name": "er_seeds", "checkpoint_from": "predvla", "seeds": [1], "pool_with": "predvla"}
    ol_seeds = {"name": "ol_seeds", "checkpoint_from": "predvla", "seeds": [1], "compare_to": "er_seeds",
                "pool_with": "A6", "eval_overrides": open_loop}
    sweep = Sweep.load(sweep_file(tmp_path, configs=[er, ol, er_seeds, ol_seeds]))
    assert sweep.configs["ol_seeds"].pool_with == "A6"
    unpooled_reference = {**er_seeds, "pool_with": None}
    with pytest.raises(SweepError, match="configuration ol_seeds: pool_with 'A6': its compare_to 'er_seeds' must "
                                         "pool with 'predvla'"):
        Sweep.load(sweep_file(tmp_path, configs=[er, ol, unpooled_reference, ol_seeds]))
    with pytest.raises(SweepError, match="configuration chained: pool_with 'er_seeds': must name a configuration "
                                         "that pools with none"):
        Sweep.load(sweep_file(tmp_path, configs=[er, er_seeds, {**er_seeds, "name": "chained",
                                                                "pool_with": "er_seeds"}]))
    with pytest.raises(SweepError, match="configuration er_seeds: pool_with 'A6': it must evaluate the model"):
        Sweep.load(sweep_file(tmp_path, configs=[er, ol, {**er_seeds, "pool_with": "A6"}]))  # open loop's seeds
    with pytest.raises(SweepError, match="configuration er_seeds: pool_with 'predvla': it must evaluate the model"):
        Sweep.load(sweep_file(tmp_path, configs=[er, {**er_seeds, "init_states": False}]))
    fast = {**er_seeds, "eval_overrides": {"recurrence_backend": "cpp"}}  # the same model, computed faster
    ol_no_pairs = {**ol_seeds, "compare_to": None}  # seed 0's pairs alone then
    assert Sweep.load(sweep_file(tmp_path, configs=[er, ol, fast, ol_no_pairs])).configs["ol_seeds"].pool_with == "A6"
    with pytest.raises(SweepError, match="unknown configuration 'nope'"):
        Sweep.load(sweep_file(tmp_path, configs=[er, {**er_seeds, "pool_with": "nope"}]))


def test_keep_every_prunes_a_finished_trainings_checkpoints(tmp_path):
    """`train.keep_every`: once a training ends, the checkpoints between every n-th step go (not the last one);
    a value that is not a multiple of save_freq is refused."""
    class FourCheckpoints(FakeLeRobot):  # steps 1-4 at save_freq 1; the fake's own last step is 2
        def __call__(self, command: list[str], log: Path) -> int:
            code = super().__call__(command, log)
            if not any(c.endswith("lerobot-eval") for c in command):
                out = Path(arg(command, "output_dir"))
                for step in (1, 3, 4):
                    (out / "checkpoints" / f"{step:06d}" / "pretrained_model").mkdir(parents=True)
            return code

    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"],
                      train={"device": "cpu", "save_freq": 1, "keep_every": 3})
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FourCheckpoints())
    assert runner.run(configs=["predvla"], progress=False)["done"] == ["predvla/libero_object/seed0"]
    out = runner.train_dir("predvla", "libero_object", 0)
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == ["000002", "000003", "last"]
    assert json.loads((out / TRAIN_DONE_FILE).read_text())["checkpoints_pruned"] == 2
    assert runner.record_path(Run("predvla", "libero_object", 0)).is_file()  # evaluated from the kept last one

    with pytest.raises(SweepError, match="train.keep_every must be a positive multiple of train.save_freq"):
        Sweep.load(sweep_file(tmp_path, train={"device": "cpu", "save_freq": 2, "keep_every": 3}))


def test_a_finished_trainings_lost_checkpoint_is_named_instead_of_evaluated(tmp_path, capsys):
    """A RUNS_DIR copied without a checkpoint its training record names: the sweep says which file names it and
    starts no evaluation of it (neither run nor dry run); the other units go on."""
    path = sweep_file(tmp_path, seeds=[0, 1], suites=["libero_object"])
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot())
    assert len(runner.run(configs=["predvla"], progress=False)["done"]) == 2
    out = runner.train_dir("predvla", "libero_object", 1)
    shutil.rmtree(out / "checkpoints")
    capsys.readouterr()

    planned = runner.pending_commands(["A6"], (0, 1))
    assert [arg(c, "seed") for c in planned] == ["0"]  # seed 0's evaluation only
    message = capsys.readouterr().err
    assert str(out / TRAIN_DONE_FILE) in message and "has no model.safetensors" in message

    fake = FakeLeRobot()
    runner.execute = fake
    outcome = runner.run(configs=["A6"], progress=False)
    assert outcome["done"] == ["A6/libero_object/seed0"] and outcome["failed"] == ["A6/libero_object/seed1"]
    assert fake.count("lerobot-eval") == 1 and fake.count("lerobot-train") == 0
    assert f"remove {out / TRAIN_DONE_FILE} to train it again" in capsys.readouterr().err


def test_runs_of_one_checkpoint_path_pair_only_when_they_evaluated_the_same_weights(tmp_path):
    """A training redone in place (its checkpoint lost) puts new weights under the old path: an evaluation of the
    new model is not paired with one of the old, and the report says so."""
    path = sweep_file(tmp_path, seeds=[0, 1], suites=["libero_object"])
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot())
    assert len(runner.run(configs=["predvla", "A6"], progress=False)["done"]) == 4
    checkpoint = runner.trained_checkpoint(
        json.loads((runner.train_dir("predvla", "libero_object", 1) / TRAIN_DONE_FILE).read_text()))
    a6 = json.loads(runner.record_path(Run("A6", "libero_object", 1)).read_text())
    assert a6["model_sha256"] == sha256_file(checkpoint / "model.safetensors")
    assert write_report(tmp_path / "runs", tmp_path / "report")["configs"]["A6"]["episodes"]["libero_object"][
        "seeds"] == [0, 1]

    save_file({"w": torch.ones(3, 4), "b": torch.zeros(5)}, str(checkpoint / "model.safetensors"))  # retrained
    runner.record_path(Run("A6", "libero_object", 1)).unlink()
    shutil.rmtree(runner.eval_dir(Run("A6", "libero_object", 1)))
    assert runner.run(configs=["A6"], progress=False)["done"] == ["A6/libero_object/seed1"]
    summary = write_report(tmp_path / "runs", tmp_path / "report")
    assert summary["configs"]["A6"]["episodes"]["libero_object"]["seeds"] == [0]
    assert summary["unpaired"] == [{"config": "A6", "against": "predvla", "suite": "libero_object", "seed": 1}]
    assert "Not paired: `A6` against `predvla`, object, seed 1" in (tmp_path / "report" / "report.md").read_text()


def test_machine_names_the_processor_its_cores_and_bf16(tmp_path):
    """Recorded beside wall times: /proc/cpuinfo's first model name and flags."""
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Some Xeon\nflags\t\t: fpu avx512f avx512_bf16\n\n"
                       "processor\t: 1\nmodel name\t: Some Xeon\nflags\t\t: fpu avx512f avx512_bf16\n")
    assert machine(cpuinfo) == f"Some Xeon, {os.cpu_count()} logical CPUs, AVX-512 bf16: yes"
    cpuinfo.write_text("model name\t: AMD EPYC\nflags\t\t: fpu avx2\n")
    assert machine(cpuinfo).endswith("AVX-512 bf16: no") and machine(cpuinfo).startswith("AMD EPYC, ")
    assert "logical CPUs" in machine(tmp_path / "absent")


def test_training_reads_the_features_only_copy(tmp_path):
    """`datasets.<suite>.train_root`: made from `root` by `predvla features-only` when missing; training reads it."""
    datasets = {s: {"repo_id": f"local/{s}", "root": f"data/{s}", "train_root": f"data/{s}_features"}
                for s in ("libero_object", "libero_spatial")}
    runner = Runner(Sweep.load(sweep_file(tmp_path, datasets=datasets)), tmp_path / "runs")
    root, copy = tmp_path / "data" / "libero_object", tmp_path / "data" / "libero_object_features"
    (stage, command), = runner.data_commands("libero_object")
    assert stage == "features_only" and command[command.index("features-only"):] == [
        "features-only", "--dataset-root", str(root), "--out", str(copy), "--repo-id", "local/libero_object"]
    train = runner.train_command(runner.sweep.configs["predvla"], "libero_object", 0)
    assert arg(train, "dataset.root") == str(copy) and arg(train, "dataset.repo_id") == "local/libero_object"
    (copy / "meta").mkdir(parents=True)
    (copy / "meta" / "info.json").write_text("{}")
    assert runner.data_commands("libero_object") == []
    # A training started on `root` resumes onto the copy (a command-line flag overrides its train_config.json).
    last = runner.train_dir("predvla", "libero_object", 0) / "checkpoints" / "last" / "pretrained_model"
    last.mkdir(parents=True)
    (last / "train_config.json").write_text("{}")
    resume = runner.pending_train_command(runner.sweep.configs["predvla"], "libero_object", 0)
    assert arg(resume, "resume") == "true" and arg(resume, "dataset.root") == str(copy)
    with pytest.raises(SweepError, match="train_root"):
        Sweep.load(sweep_file(tmp_path, datasets={**datasets, "libero_object": {"repo_id": "x", "train_root": "y"}}))


def test_data_only_makes_the_datasets_without_frames_and_stops(tmp_path, monkeypatch, capsys):
    """`predvla sweep --data-only` runs the `data` stages (here with `image_storage: none`, passed to the
    conversion) and no training or evaluation, none after `--stop-at`; an unknown storage is named."""
    from lerobot_predvla.cli import sweep as sweep_cli

    data = {"libero_object": {"hdf5": "out/hdf5", "frontend": "out/frontend", "per_task": 3, "tasks": [0],
                              "vision_weights": "random", "image_storage": "none"}}
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], data=data, eval={"device": "cpu"})
    fake = FakeData()
    monkeypatch.setattr(sweep_cli, "Runner", lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=fake, **kw))
    argv = ["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--data-only"]
    assert predvla_main([*argv, "--stop-at", "2000-01-01T00:00"]) == 0 and fake.commands == []  # --stop-at passed
    assert "stopped, data stage demos of libero_object not started" in capsys.readouterr().err
    assert predvla_main(argv) == 0
    programs = [c[c.index("lerobot_predvla.cli.main") + 1] for c in fake.commands if "lerobot_predvla.cli.main" in c]
    assert programs == ["demos", "fit-frontend", "convert"] and len(fake.commands) == 3
    assert arg_value(fake.commands[2], "--image-storage") == "none"
    assert "--threads" not in fake.commands[1] and "--threads" not in fake.commands[2]  # frontend_threads 1
    (tmp_path / "bad").mkdir()
    bad = sweep_file(tmp_path / "bad", seeds=[0], suites=["libero_object"],
                     data={"libero_object": {**data["libero_object"], "image_storage": "jpeg"}})
    assert predvla_main(["sweep", str(bad), "--runs-dir", str(tmp_path / "runs2"), "--data-only"]) == 2
    assert "data.libero_object.image_storage must be one of" in capsys.readouterr().err


def arg_value(command: list[str], flag: str) -> str:
    return command[command.index(flag) + 1]


def test_train_only_trains_what_the_runs_need_and_evaluates_nothing(tmp_path, monkeypatch, capsys):
    """`predvla sweep --train-only` runs each pending unit's training (once for a checkpoint several runs share) and no
    lerobot-eval; the next call without it evaluates from those checkpoints without training again."""
    from lerobot_predvla.cli import sweep as sweep_cli

    path = sweep_file(tmp_path)
    fake = FakeLeRobot()
    monkeypatch.setattr(sweep_cli, "Runner", lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=fake, **kw))
    assert predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--train-only"]) == 0
    assert fake.count("lerobot-train") == 6 and fake.count("lerobot-eval") == 0
    assert "6 trainings finished, 0 failed (no evaluation)" in capsys.readouterr().out
    assert not (tmp_path / "runs" / "records").exists()
    later = FakeLeRobot()
    monkeypatch.setattr(sweep_cli, "Runner", lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=later, **kw))
    assert predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs")]) == 0
    assert later.count("lerobot-train") == 0 and later.count("lerobot-eval") == 10
