"""The training posteriors' row-wise Adam (posterior_store.py): per row exactly torch.optim.Adam, O(batch)."""

import pytest
import torch

from lerobot_predvla.policies.predvla.posterior_store import PosteriorStore
from lerobot_predvla.utils.safe_loading import CheckpointError

EPISODES, LENGTH, DIM, LR = 6, 5, 4, 1e-2


def store(moments_dtype: str = "float32") -> PosteriorStore:
    s = PosteriorStore(EPISODES, LENGTH, DIM, lr=LR, moments_dtype=moments_dtype)
    with torch.no_grad():
        s.latents.copy_(torch.randn(EPISODES, LENGTH, DIM, generator=torch.Generator().manual_seed(0)))
    return s


def target(seed: int) -> torch.Tensor:
    return torch.randn(EPISODES, LENGTH, DIM, generator=torch.Generator().manual_seed(seed))


def train_step(s: PosteriorStore, episodes: list[int], seed: int) -> None:
    """A quadratic loss on the batch's rows, whose gradient differs per row and per step."""
    index = torch.tensor(episodes)
    c_q = s.gather(index)  # (LENGTH, batch, DIM)
    ((c_q - target(seed)[index].transpose(0, 1)) ** 2).sum().mul(0.5).backward()
    s.step()


def test_on_batches_of_every_episode_it_is_dense_adam():
    """With every demonstration in every batch, the row-wise step equals torch.optim.Adam on the whole store."""
    s = store()
    dense = torch.nn.Parameter(s.latents.clone())
    adam = torch.optim.Adam([dense], lr=LR)
    for seed in range(5):
        train_step(s, list(range(EPISODES)), seed)
        adam.zero_grad()
        ((dense - target(seed)) ** 2).sum().mul(0.5).backward()
        adam.step()
    torch.testing.assert_close(s.latents, dense.detach())
    torch.testing.assert_close(s.exp_avg, adam.state[dense]["exp_avg"])
    torch.testing.assert_close(s.exp_avg_sq, adam.state[dense]["exp_avg_sq"])


def test_each_row_is_its_own_adam_and_absent_rows_are_untouched():
    """A row stepped k times, in batches with other rows, equals Adam run on that row alone with the same k
    gradients; rows never in a batch keep their posteriors and moments bit for bit."""
    s = store()
    start = s.latents.clone()
    batches = [[0, 2], [2, 3], [3, 0, 2], [2]]
    for seed, episodes in enumerate(batches):
        train_step(s, episodes, seed)
    row = torch.nn.Parameter(start[2].clone())
    adam = torch.optim.Adam([row], lr=LR)
    for seed in range(len(batches)):  # row 2 is in all four batches
        adam.zero_grad()
        ((row - target(seed)[2]) ** 2).sum().mul(0.5).backward()
        adam.step()
    torch.testing.assert_close(s.latents[2], row.detach())
    assert s.steps.tolist() == [2, 0, 4, 2, 0, 0]
    for untouched in (1, 4, 5):
        assert torch.equal(s.latents[untouched], start[untouched])
        assert s.exp_avg[untouched].abs().sum() == 0 and s.exp_avg_sq[untouched].abs().sum() == 0


def test_a_row_twice_in_one_batch_gets_one_step_with_the_summed_gradient():
    s, twice = store(), store()
    train_step(s, [1, 1, 4], 0)
    index = torch.tensor([1, 4])
    c_q = twice.gather(index)
    weight = torch.tensor([2.0, 1.0])[None, :, None]  # row 1's loss counted twice, as the duplicate does
    (((c_q - target(0)[index].transpose(0, 1)) ** 2) * weight).sum().mul(0.5).backward()
    twice.step()
    assert s.steps.tolist() == twice.steps.tolist() == [0, 1, 0, 0, 1, 0]
    torch.testing.assert_close(s.latents, twice.latents)


def test_no_gradient_no_step_and_evaluation_never_queues():
    s = store()
    before = s.state()
    s.gather(torch.tensor([0, 1]))  # a forward whose loss never reached backward (e.g. a skipped batch)
    assert s.step() == 0
    with torch.no_grad():
        s.gather(torch.tensor([2]))
    s.eval()
    s.gather(torch.tensor([3]))
    assert s.pending_gradients() == [] and s.step() == 0
    for key, value in s.state().items():
        assert torch.equal(value, before[key])


def test_save_and_resume_continue_exactly(tmp_path):
    s, resumed = store(), PosteriorStore(EPISODES, LENGTH, DIM, lr=LR)
    train_step(s, [0, 3], 0)
    s.save(tmp_path)
    assert not list(tmp_path.glob(".*.tmp"))  # written under a temporary name, then renamed
    resumed.assign(resumed.read(tmp_path))
    for st, episodes in ((s, [3, 5]), (resumed, [3, 5])):
        train_step(st, episodes, 1)
    for key, value in s.state().items():
        assert torch.equal(resumed.state()[key], value), key


def test_a_store_of_another_dataset_or_dtype_fails_to_load_with_one_line(tmp_path):
    store().save(tmp_path)
    with pytest.raises(CheckpointError, match="'latents' is \\(6, 5, 4\\) torch.float32, this config needs"):
        PosteriorStore(EPISODES + 1, LENGTH, DIM, lr=LR).read(tmp_path)
    with pytest.raises(CheckpointError, match="torch.bfloat16"):
        PosteriorStore(EPISODES, LENGTH, DIM, lr=LR, moments_dtype="bfloat16").read(tmp_path)
    with pytest.raises(ValueError, match="float16"):
        PosteriorStore(EPISODES, LENGTH, DIM, lr=LR, moments_dtype="float16")


def test_bfloat16_moments_save_a_third_of_the_memory_and_follow_float32():
    full, half = store(), store("bfloat16")
    size = sum(t.numel() * t.element_size() for t in (full.latents, full.exp_avg, full.exp_avg_sq))
    assert sum(t.numel() * t.element_size() for t in (half.latents, half.exp_avg, half.exp_avg_sq)) == size * 2 // 3
    for seed in range(5):
        train_step(full, [0, 1, 2], seed)
        train_step(half, [0, 1, 2], seed)
    assert half.exp_avg.dtype == torch.bfloat16 and half.latents.dtype == torch.float32
    moved = (full.latents[:3] - store().latents[:3]).abs().mean()
    assert (half.latents[:3] - full.latents[:3]).abs().mean() < 0.02 * moved


def test_the_bench_training_step_with_a_store_trains_the_batch_rows_only():
    """`predvla bench`'s store_step_ms_* step: network and the gathered rows are stepped, nothing else."""
    from benchmarks.bench_core import randomised_model, train_step_fn, training_data
    from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

    model = randomised_model(PredVLAConfig(device="cpu"))
    data = training_data(model.config, 2, 6)
    s = PosteriorStore(50, 6, data["c_q"].shape[-1], lr=LR)
    step = train_step_fn(model, model.rollout, data, s)
    losses = [step() for _ in range(3)]
    assert all(torch.isfinite(torch.tensor(losses)))
    assert s.steps.sum() <= 6 and (s.latents.abs().sum((1, 2)) > 0).sum() == (s.steps > 0).sum() > 0


def test_dense_store_is_torch_adam_on_the_whole_store():
    """`dense=True` (`--policy.posterior_adam=dense`) on partial batches: torch.optim.Adam on one tensor, whose
    absent rows see a zero gradient (their moments decay and stale momentum keeps moving them)."""
    s = PosteriorStore(EPISODES, LENGTH, DIM, lr=LR, dense=True)
    with torch.no_grad():
        s.latents.copy_(store().latents)
    dense = torch.nn.Parameter(s.latents.clone())
    adam = torch.optim.Adam([dense], lr=LR)
    batches = [[0, 2], [2, 3], [3, 0, 2], [2]]
    for seed, episodes in enumerate(batches):
        train_step(s, episodes, seed)
        adam.zero_grad()
        index = torch.tensor(episodes)
        ((dense[index] - target(seed)[index]) ** 2).sum().mul(0.5).backward()
        adam.step()
    torch.testing.assert_close(s.latents, dense.detach())
    torch.testing.assert_close(s.exp_avg, adam.state[dense]["exp_avg"])
    assert not torch.equal(s.latents[3], store().latents[3])  # row 3 moved on in batch 4, where it was absent
