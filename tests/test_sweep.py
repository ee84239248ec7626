"""`predvla sweep`: run records, skipping, resuming, sharding and commands (fake executor); one real
lerobot-train run through the runner; the posterior store under DistributedDataParallel (gloo, CPU)."""

import argparse
import faulthandler
import json
import os
import shutil
import time
from datetime import timedelta
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
import yaml
from safetensors.torch import load_file, save_file

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.experiments.eval_info import EvalInfoError, parse_eval_info
from lerobot_predvla.experiments.report import write_report
from lerobot_predvla.experiments.sweep import (
    TRAIN_DONE_FILE,
    Run,
    Runner,
    Sweep,
    SweepError,
    parse_shard,
    subprocess_executor,
)
from lerobot_predvla.utils.manifest import sha256_file
from lerobot_predvla.utils.versions import machine


def sweep_file(tmp_path: Path, **changes) -> Path:
    (tmp_path / "L3.json").write_text(json.dumps({"type": "predvla", "er_iterations": 0, "tau": [1, 1, 1, 1]}))
    spec = {
        "seeds": [0, 1],
        "suites": ["libero_object", "libero_spatial"],
        "datasets": {s: {"repo_id": f"local/{s}", "root": f"data/{s}"} for s in ("libero_object", "libero_spatial")},
        "train": {"device": "cpu"},
        "eval": {"device": "cpu"},
        "configs": [
            {"name": "predvla", "group": "main", "suite_overrides": {"libero_10": {"sequence_length": 500}}},
            {"name": "A6", "group": "ablation", "checkpoint_from": "predvla", "compare_to": "predvla",
             "eval_overrides": {"er_iterations": 0}, "label": "- Online ER"},
            {"name": "L3", "group": "ladder", "policy": "L3.json", "suites": ["libero_object"]},
        ],
        **changes,
    }
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def cli_flags(**given) -> argparse.Namespace:
    """`predvla sweep`'s protocol flags as parsed: None (not given) except `given`."""
    names = ("seeds", "suites", "steps", "n_episodes", "episode_length", "device", "accelerate_processes",
             "eval_workers")
    return argparse.Namespace(**{**dict.fromkeys(names), **given})


def arg(command: list[str], name: str) -> str | None:
    return next((c.split("=", 1)[1] for c in command if c.startswith(f"--{name}=")), None)


class FakeLeRobot:
    """Stands in for lerobot-train / lerobot-eval: writes what they would write, records every command."""

    def __init__(self, kill_training: int = 0):
        self.commands: list[list[str]] = []
        self.kill_training = kill_training  # the first n trainings die after their first checkpoint

    def __call__(self, command: list[str], log: Path) -> int:
        self.commands.append(command)
        if any(c.endswith("lerobot-eval") for c in command):
            out = Path(arg(command, "output_dir"))
            out.mkdir(parents=True)
            seed, n = int(arg(command, "seed")), int(arg(command, "eval.n_episodes"))
            per_task = [{"task_group": arg(command, "env.task"), "task_id": t,
                         "metrics": {"successes": [i < n - t - seed for i in range(n)], "sum_rewards": [0] * n}}
                        for t in json.loads(arg(command, "env.task_ids") or "[0, 1, 2]")]
            (out / "eval_info.json").write_text(json.dumps({"per_task": per_task, "overall": {}}))
            return 0
        if arg(command, "config_path"):  # resume
            out = Path(arg(command, "config_path")).parents[3]
        else:
            out = Path(arg(command, "output_dir"))
            assert not out.exists(), "lerobot-train refuses an existing output_dir without --resume"
        ckpt = out / "checkpoints" / "000002" / "pretrained_model"
        ckpt.mkdir(parents=True, exist_ok=True)
        (ckpt / "train_config.json").write_text("{}")
        if not (out / "checkpoints" / "last").exists():
            (out / "checkpoints" / "last").symlink_to("000002")
        if self.kill_training:
            self.kill_training -= 1
            return -9
        save_file({"w": torch.zeros(3, 4), "b": torch.zeros(5)}, str(ckpt / "model.safetensors"))
        return 0

    def count(self, program: str) -> int:
        return sum(any(c.endswith(program) for c in cmd) for cmd in self.commands)


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
    assert {"lerobot", "torch", "python", "machine"} <= set(record["versions"])
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


@pytest.mark.slow
def test_real_lerobot_train_through_the_runner_and_publish(synthetic_dataset, tmp_path):
    """The runner's lerobot-train command works as generated (evaluation faked: no LIBERO in tests). `train.publish`:
    the finished training's model is written where the template says, without posteriors or optimizer state; the
    training record and the evaluation name that copy, which loads as a policy. A folder holding other weights is
    refused, never overwritten; a bad template is refused when the sweep file is read."""
    from lerobot_predvla import PredVLAPolicy
    from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE

    dataset = {"repo_id": "local/predvla_synthetic", "root": str(synthetic_dataset)}
    train = {"device": "cpu", "steps": 2, "batch_size": 2, "save_freq": 2, "publish": "published/{config}_seed{seed}",
             "args": ["--num_workers=0", "--policy.sequence_length=32"]}
    path = sweep_file(tmp_path, seeds=[0], suites=["libero_object"], datasets={"libero_object": dataset}, train=train)
    fake = FakeLeRobot()

    def execute(command: list[str], log: Path) -> int:
        return fake(command, log) if any(c.endswith("lerobot-eval") for c in command) else subprocess_executor(
            command, log)

    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=execute)
    outcome = runner.run(configs=["predvla"], progress=False)
    log = runner.log_path("predvla", "libero_object", 0, "train")
    assert outcome["done"] == ["predvla/libero_object/seed0"], log.read_text()[-3000:]
    record = json.loads(runner.record_path(Run("predvla", "libero_object", 0)).read_text())
    assert record["parameters"] == 675_732 and record["steps"] == 2
    published = tmp_path / "published" / "predvla_seed0"
    trained = json.loads((runner.train_dir("predvla", "libero_object", 0) / TRAIN_DONE_FILE).read_text())
    assert (runner.runs_dir / trained["checkpoint"]).resolve() == published.resolve()
    last = (runner.runs_dir / trained["trained_checkpoint"]).resolve()
    assert (published / "model.safetensors").read_bytes() == (last / "model.safetensors").read_bytes()
    assert (last / POSTERIOR_STORE_FILE).is_file() and not (published / POSTERIOR_STORE_FILE).exists()
    assert not (published / "training_state").exists()
    assert arg(fake.commands[-1], "policy.path") == str(published.resolve())
    assert PredVLAPolicy.from_pretrained(published).config.type == "predvla"

    spec = runner.sweep.configs["predvla"]  # a sweep stopped after the copy: the same weights there are kept
    assert runner.publish_model(spec, "libero_object", 0, last) == runner.publish_dir(spec, "libero_object", 0)
    save_file({"w": torch.ones(2)}, str(published / "model.safetensors"))  # another training's weights: refused
    assert runner.publish_model(spec, "libero_object", 0, last) is False
    assert load_file(str(published / "model.safetensors"))["w"].tolist() == [1.0, 1.0]

    with pytest.raises(SweepError, match=r"train.publish 'published/\{run\}': expected a folder with only"):
        Sweep.load(sweep_file(tmp_path, train={**train, "publish": "published/{run}"}))


# ----- posterior store under DDP -----------------------------------------------------------------------------
def _policy(dataset_root: str):
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    from lerobot_predvla import PredVLAConfig

    torch.manual_seed(0)
    meta = LeRobotDatasetMetadata("local/predvla_synthetic", root=dataset_root)
    return make_policy(PredVLAConfig(device="cpu", sequence_length=16), ds_meta=meta)


RANK_EPISODES = ([0, 1], [1, 6])  # episode 1 is in both processes' batches
DDP_TIMEOUT = timedelta(minutes=5)  # the workers finish in ~30 s on 2 cores beside a training


def _ddp_worker(rank: int, world: int, init_file: str, dataset_root: str, out: str) -> None:
    # A worker stuck past DDP_TIMEOUT prints every thread's stack and exits, so a hang fails with where it hung
    # (mp.spawn then raises) instead of waiting for pytest-timeout, which sees only the parent's stack.
    faulthandler.dump_traceback_later(DDP_TIMEOUT.total_seconds(), exit=True)
    torch.set_num_threads(1)
    dist.init_process_group("gloo", init_method=f"file://{init_file}", rank=rank, world_size=world,
                            timeout=DDP_TIMEOUT)
    policy = _policy(dataset_root)
    ddp = torch.nn.parallel.DistributedDataParallel(policy)
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=1e-3)
    loss, _ = ddp({"episode_index": torch.tensor(RANK_EPISODES[rank])})
    loss.backward()
    optimizer.step()
    policy.update()  # exchanges only the two processes' batch rows and their gradients
    torch.save(policy.posterior_store.state(), os.path.join(out, f"rank{rank}.pt"))
    dist.barrier()  # neither process tears the group down while the other may still be in a collective
    dist.destroy_process_group()
    faulthandler.cancel_dump_traceback_later()


@pytest.mark.slow
def test_posterior_store_stays_consistent_under_ddp(synthetic_dataset, tmp_path):
    """Two processes, different episodes: the batch rows' gradients are all-gathered and averaged like DDP
    averages a parameter's, so both replicas take the same Adam step, equal to one process seeing both batches
    with the averaged loss; DDP itself neither broadcasts nor all-reduces the store."""
    mp.spawn(_ddp_worker, args=(2, str(tmp_path / "init"), str(synthetic_dataset), str(tmp_path)), nprocs=2)
    replicas = [torch.load(tmp_path / f"rank{r}.pt") for r in range(2)]
    for key in replicas[0]:
        assert torch.equal(replicas[0][key], replicas[1][key]), key

    policy = _policy(str(synthetic_dataset))
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=1e-3)
    losses = [policy({"episode_index": torch.tensor(e)})[0] for e in RANK_EPISODES]
    (sum(losses) / 2).backward()
    optimizer.step()
    policy.update()
    for key, value in policy.posterior_store.state().items():
        torch.testing.assert_close(replicas[0][key], value, rtol=1e-5, atol=1e-6)
    latents = replicas[0]["latents"]
    touched = sorted({e for episodes in RANK_EPISODES for e in episodes})
    untouched = [e for e in range(latents.shape[0]) if e not in touched]
    assert latents[touched].abs().sum() > 0 and latents[untouched].abs().sum() == 0
    assert replicas[0]["steps"].tolist() == [1 if e in touched else 0 for e in range(latents.shape[0])]


def test_the_paper_sweep_file_is_valid():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    assert sweep.settings.n_episodes == 50 and sweep.settings.episode_length == 600 and len(sweep.settings.seeds) == 14
    assert sweep.configs["A6"].checkpoint_from == "predvla" and sweep.configs["L2b"].branch
    assert len(sweep.runs(["predvla"])) == 56 and len(sweep.runs(["A1"])) == 21


def test_the_libero_demo_sweep_file_is_valid():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_demo.yaml")
    assert sweep.settings.train_device == "cpu" and sweep.settings.eval_args == ["--env.task_ids=[0]"]
    assert len(sweep.runs()) == 6 and sweep.configs["A4"].compare_to == "predvla"
    assert sweep.settings.datasets["libero_object"]["root"].endswith("outputs/libero_demo/dataset")


def test_randomised_resets_evaluate_from_their_own_seed_and_are_recorded(tmp_path):
    configs = [{"name": "predvla", "group": "main"},
               {"name": "fresh", "group": "ablation", "checkpoint_from": "predvla", "init_states": False,
                "eval_seed": 1000}]
    fake = FakeLeRobot()
    runner = Runner(Sweep.load(sweep_file(tmp_path, configs=configs, seeds=[0], suites=["libero_object"])),
                    tmp_path / "runs", execute=fake)
    assert not runner.run(progress=False)["failed"]
    evals = {arg(c, "output_dir").split("/eval/")[1].split("/")[0]: c for c in fake.commands
             if c[0].endswith("lerobot-eval")}
    assert arg(evals["predvla"], "env.init_states") == "true" and arg(evals["predvla"], "seed") == "0"
    assert arg(evals["fresh"], "env.init_states") == "false" and arg(evals["fresh"], "seed") == "1000"
    assert fake.count("lerobot-train") == 1  # the resets reuse the trained checkpoint
    record = json.loads((tmp_path / "runs/records/fresh/libero_object/seed0.json").read_text())
    assert record["init_states"] is False and record["eval_seed"] == 1000
    base = json.loads((tmp_path / "runs/records/predvla/libero_object/seed0.json").read_text())
    assert base["init_states"] is True and base["eval_seed"] == 0


def test_the_libero_object_cpu_sweep_file_is_valid(tmp_path):
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_object_cpu.yaml")
    assert sweep.settings.eval_tasks == list(range(10))
    assert sweep.settings.data["libero_object"].language_from == "libero"
    runner = Runner(sweep, tmp_path)
    train = runner.train_command(sweep.configs["predvla_cpu"], "libero_object", 0)
    assert "--policy.open_loop_weight=1.0" in train and "--policy.optimizer_lr=0.001" in train
    assert "--steps=4000" in train and not any(a.startswith("--policy.complexity_weights") for a in train)
    # The shipped checkpoints/predvla_libero_object: the recipe trained 8,000 steps.
    shipped = runner.train_command(sweep.configs["predvla_cpu_8k"], "libero_object", 0)
    assert "--steps=8000" in shipped and "--policy.open_loop_weight=1.0" in shipped
    assert sweep.configs["predvla_cpu_8k_open_loop"].checkpoint_from == "predvla_cpu_8k"
    ablation = runner.train_command(sweep.configs["predvla_cpu_no_open_loop_term"], "libero_object", 0)
    assert "--policy.open_loop_weight=0.0" in ablation
    assert "--policy.type=predvla_bc_rnn" in runner.train_command(sweep.configs["B2"], "libero_object", 0)
    fresh = sweep.configs["predvla_cpu_8k_random_resets"]
    assert fresh.checkpoint_from == "predvla_cpu_8k" and not fresh.init_states and fresh.eval_seed == 1000


def test_the_reading_screen_changes_one_reading_per_configuration(tmp_path):
    """configs/sweeps/libero_object_reading.yaml (docs/research/dynamics.md): each training reading reaches
    lerobot-train as the config field it names, a dict-typed field whole as JSON (draccus parses no other form)."""
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_object_reading.yaml")
    runner = Runner(sweep, tmp_path)
    train = {name: runner.train_command(sweep.configs[name], "libero_object", 0)
             for name in ("table2", "mean", "scaled", "dense", "open_loop_term")}
    assert all("--steps=10000" in c and "--batch_size=32" in c for c in train.values())
    assert "--policy.complexity_reduction=mean" in train["mean"]
    assert "--policy.posterior_adam=dense" in train["dense"]
    assert "--policy.open_loop_weight=1.0" in train["open_loop_term"]
    mapping = [a for a in train["scaled"] if a.startswith("--policy.normalization_mapping=")]
    assert len(mapping) == 1 and json.loads(mapping[0].split("=", 1)[1])["STATE"] == "MEAN_STD"
    readings = {"--policy.type=predvla", "--policy.push_to_hub=false", "--policy.device=cpu"}
    assert {a for a in train["table2"] if a.startswith("--policy.")} == readings  # the defaults: Table 2
    assert sweep.configs["scaled_gd"].eval_overrides == {"er_optimizer": "gd"}
    assert sweep.settings.eval_tasks == [1, 4, 7] and sweep.settings.n_episodes == 10


def test_the_init_noise_sweep_records_demonstrations_that_start_like_the_official_init_states(tmp_path):
    """The arm's initial joint noise, the half-turn rule and the holds after success reach `predvla demos`;
    libero_object_cpu.yaml keeps the fixed start."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    for name, noise, half_turn, hold in (("libero_object_cpu_init_noise.yaml", "0.02", "nearest", "0"),
                                         ("libero_object_cpu_init_noise_wrist.yaml", "0.02", "wrist_centre", "0"),
                                         ("libero_object_cpu_hold.yaml", "0.02", "wrist_centre", "40"),
                                         ("libero_object_cpu.yaml", "0.0", "nearest", "0")):
        sweep = Sweep.load(sweeps / name)
        spec = sweep.settings.data["libero_object"]  # outputs in tmp_path: nothing made on this machine counts
        spec.hdf5, spec.frontend = str(tmp_path / name / "hdf5"), str(tmp_path / name / "frontend")
        sweep.settings.datasets["libero_object"]["root"] = str(tmp_path / name / "dataset")
        stage, command = Runner(sweep, tmp_path).data_commands("libero_object")[0]
        assert stage == "demos" and command[command.index("--init-noise") + 1] == noise
        assert command[command.index("--half-turn") + 1] == half_turn
        assert command[command.index("--hold-steps") + 1] == hold


def test_paper_sweep_reads_every_policy_file():
    """configs/policy/*.json are `lerobot-train --config_path` files; the sweep takes their nested policy."""
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    base = Path(__file__).parents[1] / "configs" / "sweeps"
    types = {name: spec.policy_args(base, "libero_object")[0] for name, spec in sweep.configs.items()}
    assert types["B1"] == "--policy.type=predvla_bc_transformer" and types["B2"] == "--policy.type=predvla_bc_rnn"
    assert types["L3"] == "--policy.type=predvla_ladder"
    assert "--policy.chunk_size=8" in sweep.configs["B3"].policy_args(base, "libero_object")


def test_corruption_points_evaluate_with_an_unrelated_episode_of_another_suite(tmp_path):
    corruption = {"name": "Cp25", "group": "corruption", "checkpoint_from": "predvla", "compare_to": "predvla",
                  "corruption": {"channel": "proprio", "alpha": 0.25, "open_loop": "A6", "episode": 3},
                  "suites": ["libero_object"]}
    path = sweep_file(tmp_path, configs=[{"name": "predvla"}, corruption])
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot())
    command = runner.eval_command(Run("Cp25", "libero_object", 0), tmp_path / "ckpt")
    assert arg(command, "policy.er_corruption_channel") == "proprio"
    assert arg(command, "policy.er_corruption_alpha") == "0.25"
    assert arg(command, "policy.er_corruption_episode") == "3"
    # libero_object is corrupted from libero_spatial's dataset, libero_spatial from libero_goal's (missing here).
    assert arg(command, "policy.er_corruption_root") == str((tmp_path / "data" / "libero_spatial").resolve())
    assert arg(runner.eval_command(Run("predvla", "libero_object", 0), tmp_path / "ckpt"),
               "policy.er_corruption_channel") is None
    with pytest.raises(SweepError, match="corruption source suites \\['libero_goal'\\]"):
        Sweep.load(sweep_file(tmp_path, configs=[{"name": "predvla"}, {**corruption, "suites": ["libero_spatial"]}]))
    with pytest.raises(SweepError, match="channel"):
        Sweep.load(sweep_file(tmp_path, configs=[{"name": "predvla"}, {**corruption, "corruption": {"alpha": 1}}]))
    hub_only = {s: {"repo_id": f"local/{s}"} for s in ("libero_object", "libero_spatial")}
    with pytest.raises(SweepError, match=r"corruption source datasets of \['libero_spatial'\] need a local `root`"):
        Sweep.load(sweep_file(tmp_path, datasets=hub_only, configs=[{"name": "predvla"}, corruption]))
    runner.run(progress=False)
    record = json.loads(runner.record_path(Run("Cp25", "libero_object", 0)).read_text())
    assert record["group"] == "corruption" and record["corruption"]["alpha"] == 0.25


def test_the_paper_sweep_has_every_corruption_point():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    points = {(s.corruption["channel"], s.corruption["alpha"]) for s in sweep.configs.values() if s.corruption}
    assert points == {(c, a) for c in ("vision", "proprio") for a in (0.25, 0.5, 0.75, 1.0)}


class FakeData(FakeLeRobot):
    """Also stands in for `predvla demos`, `fit-frontend` and `convert`, writing the files they would write."""

    def __call__(self, command: list[str], log: Path) -> int:
        if "lerobot_predvla.cli.main" not in command:
            return super().__call__(command, log)
        self.commands.append(command)
        stage = command[command.index("lerobot_predvla.cli.main") + 1]
        value = dict(zip(command, command[1:], strict=False))
        if stage == "demos":
            from lerobot_predvla.sims.libero.env import task_spec
            from lerobot_predvla.sims.libero.hdf5_layout import task_file

            for task in value["--tasks"].split(","):
                path = task_file(Path(value["--out"]), task_spec(value["--suite"], int(task)))
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text("demos")
        elif stage == "fit-frontend":
            Path(value["--out"]).mkdir(parents=True)
            (Path(value["--out"]) / "metadata.json").write_text("{}")
        else:
            (Path(value["--out"]) / "meta").mkdir(parents=True)
            (Path(value["--out"]) / "meta" / "info.json").write_text("{}")
        return 0


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
