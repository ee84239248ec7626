"""Learning-rate selection on held-out demonstrations (`lr_sweep`, sweep/lr_selection.py): the plan and the
resumable stages with a fake `lerobot-train`, and the real selection through LeRobot's `--dataset.eval_split`."""

import json
from pathlib import Path

import pytest
import torch
import yaml
from safetensors.torch import save_file

from lerobot_predvla.policies.common.training_guard import NONFINITE_STOP
from lerobot_predvla.sweep import TRAIN_DONE_FILE, Run, Runner, Sweep, SweepError, subprocess_executor
from lerobot_predvla.sweep.lr_selection import (
    PENDING_LR,
    LRSweep,
    candidate_path,
    choose,
    heldout_losses,
    selection_path,
)

SUITE = "libero_object"


def arg(command: list[str], name: str) -> str | None:
    return next((c.split("=", 1)[1] for c in command if c.startswith(f"--{name}=")), None)


def sweep_file(tmp_path: Path, dataset: dict | None = None, train: dict | None = None, **lr_sweep) -> Path:
    spec = {
        "seeds": [0, 1],
        "suites": [SUITE],
        "datasets": {SUITE: dataset or {"repo_id": "local/x", "root": "data"}},
        "train": train or {"device": "cpu"},
        "eval": {"device": "cpu", "n_episodes": 2},
        "configs": [{"name": "B2", "group": "baseline", "policy": "predvla_bc_rnn", "steps": 50,
                     "lr_sweep": {"rates": [1e-4, 1e-3, 1e-2], "steps": 10, "eval_split": 0.25, **lr_sweep}}],
    }
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


class FakeTrainer:
    """Stands in for lerobot-train and lerobot-eval: a checkpoint, and a held-out loss line per rate in the log
    (`losses`: rate -> loss, or "diverge" for the training guard's stop)."""

    def __init__(self, losses: dict[float, float | str]):
        self.losses = losses
        self.commands: list[list[str]] = []

    def __call__(self, command: list[str], log: Path) -> int:
        self.commands.append(command)
        log.parent.mkdir(parents=True, exist_ok=True)
        if any(c.endswith("lerobot-eval") for c in command):
            out = Path(arg(command, "output_dir"))
            out.mkdir(parents=True)
            per_task = [{"task_id": 0, "metrics": {"successes": [True, False], "sum_rewards": [0, 0]}}]
            (out / "eval_info.json").write_text(json.dumps({"per_task": per_task, "overall": {}}))
            return 0
        loss = self.losses[float(arg(command, "policy.optimizer_lr"))] if arg(command, "eval_steps") else None
        if loss == "diverge":
            log.write_text(f"predvla_bc_rnn: non-finite loss at training step 3 (loss terms: action_nll=nan); "
                           f"{NONFINITE_STOP} (--policy.on_nonfinite_training=skip skips such batches).\n")
            return 1
        ckpt = Path(arg(command, "output_dir")) / "checkpoints" / "000010" / "pretrained_model"
        ckpt.mkdir(parents=True)
        (ckpt / "train_config.json").write_text("{}")
        (ckpt.parents[1] / "last").symlink_to("000010")
        save_file({"w": torch.zeros(2)}, str(ckpt / "model.safetensors"))
        if loss is not None:  # tqdm and logging share the line, as in a real log
            log.write_text(f"Training: 100%|##| 10/10]INFO 2026 lerobot_train.py:673 step {arg(command, 'steps')}: "
                           f"eval_loss={loss:.4f}\nstep 5: eval_loss=9.0000\n")
        return 0

    def trainings(self) -> list[list[str]]:
        return [c for c in self.commands if any(x.endswith("lerobot-train") for x in c)]


def test_the_dry_run_plans_the_candidates_then_the_chosen_rate(tmp_path):
    runner = Runner(Sweep.load(sweep_file(tmp_path)), tmp_path / "runs")
    trainings = [c for c in runner.pending_commands(None, (0, 1)) if c[0].endswith("lerobot-train")]
    candidates = trainings[:3]
    assert [arg(c, "policy.optimizer_lr") for c in candidates] == ["0.0001", "0.001", "0.01"]
    assert all(arg(c, "dataset.eval_split") == "0.25" and arg(c, "eval_steps") == "10" and arg(c, "steps") == "10"
               and arg(c, "seed") == "0" for c in candidates)
    assert arg(candidates[1], "output_dir") == str(tmp_path / "runs/train/B2_lr0.001" / SUITE / "seed0")
    # One selection serves both seeds: the full trainings wait for it and hold nothing out.
    assert [arg(c, "policy.optimizer_lr") for c in trainings[3:]] == [PENDING_LR, PENDING_LR]
    assert all(arg(c, "steps") == "50" and arg(c, "dataset.eval_split") is None for c in trainings[3:])


def test_the_lowest_heldout_loss_wins_and_every_stage_is_skipped_once_done(tmp_path):
    fake = FakeTrainer({1e-4: -1.5, 1e-3: -2.25, 1e-2: "diverge"})
    runner = Runner(Sweep.load(sweep_file(tmp_path, eval_every=5)), tmp_path / "runs", execute=fake)
    with pytest.MonkeyPatch.context() as patch:  # the fake has no dataset to read the held-out episodes from
        patch.setattr("lerobot_predvla.sweep.training.heldout_episodes", lambda *a: {"task": [3]})
        outcome = runner.run(progress=False)
    assert outcome["done"] == ["B2/libero_object/seed0", "B2/libero_object/seed1"], outcome
    selection = json.loads(selection_path(tmp_path / "runs", "B2", SUITE).read_text())
    assert selection["chosen_lr"] == 1e-3 and selection["heldout_nll"] == {"0.0001": -1.5, "0.001": -2.25, "0.01": None}
    assert selection["heldout_episodes"] == {"task": [3]} and selection["eval_split"] == 0.25
    diverged = json.loads(candidate_path(tmp_path / "runs", "B2", SUITE, 1e-2).read_text())
    assert NONFINITE_STOP in diverged["diverged"]
    best = json.loads(candidate_path(tmp_path / "runs", "B2", SUITE, 1e-3).read_text())
    assert best["heldout_curve"] == {"5": 9.0, "10": -2.25}
    full = [c for c in fake.trainings() if arg(c, "steps") == "50"]
    assert len(fake.trainings()) == 5 and [arg(c, "seed") for c in full] == ["0", "1"]
    assert all(arg(c, "policy.optimizer_lr") == "0.001" and arg(c, "dataset.eval_split") is None for c in full)
    record = json.loads(runner.record_path(Run("B2", SUITE, 1)).read_text())
    assert "--policy.optimizer_lr=0.001" in record["commands"]["train"]

    # A later call with the full trainings gone reuses the selection: no candidate trains again.
    for seed in (0, 1):
        (runner.train_dir("B2", SUITE, seed) / TRAIN_DONE_FILE).unlink()
        runner.record_path(Run("B2", SUITE, seed)).unlink()
    again = FakeTrainer({})
    runner.execute = again
    assert runner.pending_commands(None, (0, 1))[0] == runner.resume_command(runner.train_dir("B2", SUITE, 0), SUITE)
    assert runner.select_lr(runner.sweep.configs["B2"], SUITE) == 1e-3 and again.commands == []


def test_a_candidate_that_crashes_is_retried_not_recorded(tmp_path):
    runner = Runner(Sweep.load(sweep_file(tmp_path)), tmp_path / "runs", execute=lambda command, log: 1)
    assert runner.select_lr(runner.sweep.configs["B2"], SUITE) is None
    assert not candidate_path(tmp_path / "runs", "B2", SUITE, 1e-4).exists()
    assert not selection_path(tmp_path / "runs", "B2", SUITE).exists()


@pytest.mark.parametrize(("change", "message"), [
    ({"rates": []}, "rates must be a non-empty"),
    ({"rates": [1e-3, 0.001]}, "rates must be distinct"),
    ({"eval_split": 1.0}, "eval_split must be in"),
    ({"eval_every": 3}, "eval_every must be >= 1 and divide steps"),
    ({"unknown": 1}, "unexpected keyword argument 'unknown'"),
])
def test_bad_lr_sweeps_are_refused_with_the_key(tmp_path, change, message):
    with pytest.raises(SweepError, match=message):
        Sweep.load(sweep_file(tmp_path, **change))


def test_the_chosen_rate_is_not_also_set_by_hand(tmp_path):
    raw = yaml.safe_load(sweep_file(tmp_path).read_text())
    raw["configs"][0]["policy_overrides"] = {"optimizer_lr": 1e-3}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(raw))
    with pytest.raises(SweepError, match="optimizer_lr is chosen by the sweep; remove it from policy_overrides"):
        Sweep.load(tmp_path / "sweep.yaml")


def test_choose_and_parse():
    assert choose({1e-4: -1.0, 3e-4: -3.0, 1e-3: float("nan"), 3e-3: None}) == 3e-4
    with pytest.raises(ValueError, match="no learning rate"):
        choose({1e-3: None})
    assert LRSweep([1e-3], 10).train_args() == ["--dataset.eval_split=0.1", "--eval_steps=10"]


@pytest.mark.slow  # trains with the real lerobot-train
def test_real_selection_holds_demonstrations_out_and_picks_the_lowest_heldout_nll(synthetic_dataset, tmp_path):
    """Two candidates through the real lerobot-train on the 8-episode dataset (1 of 4 episodes per task held out):
    the chosen rate has the lowest held-out NLL that LeRobot logged, and LeRobot's own split of each candidate's
    saved training config trained on no held-out episode."""
    from lerobot.configs.train import TrainPipelineConfig
    from lerobot.datasets.factory import make_train_eval_datasets

    import lerobot_policy_predvla  # noqa: F401  registers the policy types for the saved config

    dataset = {"repo_id": "local/predvla_synthetic", "root": str(synthetic_dataset)}
    train = {"device": "cpu", "batch_size": 2, "save_freq": 4, "args": ["--num_workers=0"]}
    runner = Runner(Sweep.load(sweep_file(tmp_path, dataset, train, rates=[1e-5, 3e-2], steps=4, eval_every=2)),
                    tmp_path / "runs", execute=subprocess_executor)
    spec = runner.sweep.configs["B2"]
    chosen = runner.select_lr(spec, SUITE)
    selection = json.loads(selection_path(tmp_path / "runs", "B2", SUITE).read_text())
    losses = {}
    for rate in (1e-5, 3e-2):
        log = runner.log_path(f"B2_lr{rate:g}", SUITE, 0, "train")
        curve = heldout_losses(log)
        assert sorted(curve) == [2, 4], log.read_text()[-3000:]
        losses[rate] = curve[4]
    assert selection["heldout_nll"] == {f"{r:g}": v for r, v in losses.items()}
    assert chosen == selection["chosen_lr"] == min(losses, key=losses.get)

    heldout = sorted(e for episodes in selection["heldout_episodes"].values() for e in episodes)
    assert len(selection["heldout_episodes"]) == 2 and all(len(e) == 1 for e in selection["heldout_episodes"].values())
    for rate in (1e-5, 3e-2):
        train_dir = runner.train_dir(f"B2_lr{rate:g}", SUITE, 0)
        cfg = TrainPipelineConfig.from_pretrained(train_dir / "checkpoints/last/pretrained_model")
        trained_on, held_out = make_train_eval_datasets(cfg)
        assert sorted(held_out.episodes) == heldout
        assert not set(trained_on.episodes) & set(heldout) and len(trained_on.episodes) == 6
    command = runner.train_command(spec, SUITE, 1)
    assert arg(command, "policy.optimizer_lr") == f"{chosen}" and arg(command, "dataset.eval_split") is None
