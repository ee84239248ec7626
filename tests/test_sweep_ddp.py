"""`predvla sweep` with the real lerobot-train (one run through the runner, then publishing) and the posterior store
under DistributedDataParallel (gloo, CPU)."""

import faulthandler
import json
import os
from datetime import timedelta
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp
from safetensors.torch import load_file, save_file
from sweep_factory import FakeLeRobot, arg, sweep_file

from lerobot_predvla.sweep import (
    TRAIN_DONE_FILE,
    Run,
    Runner,
    Sweep,
    SweepError,
    subprocess_executor,
)


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
