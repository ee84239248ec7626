"""Training posteriors c_q: one free variable per (episode, step, module) (Section 3.4), with row-wise Adam.

Section 3.4 makes the posteriors "model parameters, with one c^l_{q,t} for each module, time step, and
demonstration". A batch only holds a few demonstrations, so the store is not an `nn.Parameter` in LeRobot's
optimizer (which would read, decay and, under DDP, all-reduce every episode's posteriors and moments every
step). Each demonstration's posteriors are instead their own Adam problem (Table 2: learning rate
`posterior_lr`, no weight decay), stepped when the demonstration is in the batch:

- `gather` hands the forward pass a copy of the batch's rows as a leaf tensor and remembers it;
- after the optimizer step (`PredVLAPolicy.update`), `step` applies Adam to exactly those rows (duplicates
  summed, as autograd sums them through an index), with each row's own step count for the bias correction;
  under DDP the batch rows and their gradients are all-gathered (only those) and averaged over processes, as
  DDP averages a parameter's gradient;
- rows not in the batch are not read or written: their posteriors and moments keep their values.

Per row this is exactly `torch.optim.Adam` run on that demonstration's posteriors with the gradients of the
batches it was in. Dense Adam over the whole store differs only in what it does to absent rows: it decays
their moments and keeps moving them on stale momentum, which no demonstration's objective asks for. On a batch
holding every demonstration the two are identical (tested). A step costs O(batch), whatever the dataset's size.
Dense Adam is available as a reading of the paper (`dense=True`, `--policy.posterior_adam=dense`); it costs one
pass over the whole store per step.

Posteriors, moments and step counts are saved together in `posterior_store.safetensors` (training
checkpoints only; never `model.safetensors` or the Hub), so `--resume` continues exactly.
"""

import logging
from pathlib import Path

import torch
import torch.distributed as dist
from safetensors.torch import save_file
from torch import Tensor, nn

from lerobot_predvla.utils.safe_loading import check_tensors, read_safetensors

POSTERIOR_STORE_FILE = "posterior_store.safetensors"
MOMENT_DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}
STORE_TENSORS = ("latents", "exp_avg", "exp_avg_sq")
MAX_PENDING = 64  # batches gathered without a `step` before they are dropped (a loop that never calls update)


class PosteriorStore(nn.Module):
    """Posteriors of shape (num_episodes, sequence_length, 4r), keyed by `episode_index` and step.

    Args:
        num_episodes, sequence_length, posterior_dim: Shape of the store.
        lr: Adam learning rate of the posteriors (Table 2: 1e-2).
        betas, eps: Adam's coefficients (those of the network's optimizer preset).
        moments_dtype: Storage of the Adam moments: "float32", or "bfloat16" to save a third of the memory of
            large datasets (`PredVLAConfig.posterior_moments_dtype`). The posteriors themselves stay float32:
            a step of `lr` is below bfloat16's resolution for posteriors of order 1.
        dense: False (default): row-wise Adam, above. True: one Adam over the whole store, every row stepped at
            every `step` with a zero gradient where it was not in the batch (`PredVLAConfig.posterior_adam`).
    """

    def __init__(self, num_episodes: int, sequence_length: int, posterior_dim: int, lr: float,
                 betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8, moments_dtype: str = "float32",
                 dense: bool = False):
        super().__init__()
        if moments_dtype not in MOMENT_DTYPES:
            raise ValueError(f"posterior moments dtype must be one of {list(MOMENT_DTYPES)}, got {moments_dtype!r}.")
        shape = (num_episodes, sequence_length, posterior_dim)
        # Buffers, not persistent: moved by `.to()`, never part of the network's state dict.
        self.register_buffer("latents", torch.zeros(shape), persistent=False)
        for name in ("exp_avg", "exp_avg_sq"):
            self.register_buffer(name, torch.zeros(shape, dtype=MOMENT_DTYPES[moments_dtype]), persistent=False)
        self.register_buffer("steps", torch.zeros(num_episodes, dtype=torch.long), persistent=False)
        self.lr, self.betas, self.eps, self.dense = lr, betas, eps, dense
        self._pending: list[tuple[Tensor, Tensor]] = []

    @property
    def num_episodes(self) -> int:
        return self.latents.shape[0]

    def gather(self, episode_index: Tensor) -> Tensor:
        """Posteriors of the given episodes, time-major: (sequence_length, batch, 4r).

        In training mode with gradients enabled the rows are a fresh leaf that `step` later applies Adam to.
        """
        if int(episode_index.max()) >= self.num_episodes or int(episode_index.min()) < 0:
            raise IndexError(
                f"episode_index {episode_index.tolist()} outside the posterior store of "
                f"{self.num_episodes} episodes; was the policy built from this dataset's metadata?"
            )
        rows = self.latents.index_select(0, episode_index)
        if torch.is_grad_enabled() and self.training:
            rows.requires_grad_(True)
            self._pending.append((episode_index.detach().clone(), rows))
            if len(self._pending) > MAX_PENDING:
                logging.warning(
                    "PredVLA: %d training batches since the posteriors were last stepped; dropping them. Call "
                    "policy.update() after optimizer.step() (lerobot-train does).", len(self._pending)
                )
                self._pending = self._pending[-1:]
        return rows.transpose(0, 1)

    def pending_gradients(self) -> list[tuple[str, Tensor]]:
        """The leaves handed out since the last `step`, for gradient checks (name, tensor with `.grad`)."""
        return [(f"posterior_store[{index.tolist()}]", rows) for index, rows in self._pending]

    def discard_pending(self) -> None:
        """Forget the rows handed out since the last `step` (gradients taken for inspection, not training)."""
        self._pending = []

    @torch.no_grad()
    def step(self) -> int:
        """Adam on the rows gathered since the last step that received a gradient; returns how many rows."""
        if not self._pending:
            return 0
        pending, self._pending = [r for r in self._pending if r[1].grad is not None], []
        if dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1:
            index, grad = all_gather_rows(pending, self.latents)
        elif pending:
            index = torch.cat([i for i, _ in pending]).to(self.latents.device)
            grad = torch.cat([r.grad for _, r in pending])
        else:
            return 0
        if index.numel() == 0:
            return 0
        if self.dense:  # every row, with a zero gradient where it was not in the batch
            rows, inverse = torch.arange(self.num_episodes, device=index.device), index
        else:
            rows, inverse = torch.unique(index, return_inverse=True)
        g = grad.new_zeros(len(rows), *grad.shape[1:]).index_add_(0, inverse, grad)  # duplicates sum
        beta1, beta2 = self.betas
        self.steps[rows] += 1
        k = self.steps[rows].to(g.dtype)[:, None, None]  # each row's own Adam step count
        m = self.exp_avg[rows].float().lerp_(g, 1.0 - beta1)
        v = self.exp_avg_sq[rows].float().mul_(beta2).addcmul_(g, g, value=1.0 - beta2)
        # torch.optim.Adam's update with per-row bias corrections: p -= lr / bc1 * m / (sqrt(v / bc2) + eps).
        denom = (v.sqrt() / (1.0 - beta2**k).sqrt()).add_(self.eps)
        p = self.latents[rows].float() - (self.lr / (1.0 - beta1**k)) * m / denom
        for name, value in (("latents", p), ("exp_avg", m), ("exp_avg_sq", v)):
            buffer = getattr(self, name)
            buffer.index_copy_(0, rows, value.to(buffer.dtype))
        return len(rows)

    def state(self) -> dict[str, Tensor]:
        return {name: getattr(self, name).detach().cpu().contiguous() for name in (*STORE_TENSORS, "steps")}

    def save(self, directory: Path) -> None:
        tmp = directory / f".{POSTERIOR_STORE_FILE}.tmp"
        save_file(self.state(), str(tmp))
        tmp.replace(directory / POSTERIOR_STORE_FILE)

    def read(self, directory: Path) -> dict[str, Tensor] | None:
        """The store saved beside a checkpoint's weights, checked (readable, finite, of this dataset's and
        config's shapes and dtypes) but not loaded; None when there is none."""
        path = Path(directory) / POSTERIOR_STORE_FILE
        if not path.is_file():
            return None
        tensors, _ = read_safetensors(path)
        check_tensors(path, tensors, self.state())
        return tensors

    def assign(self, tensors: dict[str, Tensor]) -> None:
        for name, value in tensors.items():
            getattr(self, name).copy_(value)


def all_gather_rows(pending: list[tuple[Tensor, Tensor]], like: Tensor) -> tuple[Tensor, Tensor]:
    """Every process's batch rows and their gradients, divided by the number of processes (DDP's mean).

    Only the batch's rows travel: O(batch) per step, never the whole store.
    """
    shape = like.shape[1:]
    index = torch.cat([i for i, _ in pending]).to(like.device) if pending else like.new_zeros(0, dtype=torch.long)
    grad = (torch.cat([r.grad for _, r in pending]) if pending
            else like.new_zeros(0, *shape, dtype=torch.float32))
    world = dist.get_world_size()
    sizes = [torch.zeros(1, dtype=torch.long, device=like.device) for _ in range(world)]
    dist.all_gather(sizes, torch.tensor([len(index)], device=like.device))
    most = int(max(s.item() for s in sizes))
    padded_index = torch.cat([index, index.new_zeros(most - len(index))])
    padded_grad = torch.cat([grad, grad.new_zeros(most - len(grad), *shape)])
    indices = [torch.empty_like(padded_index) for _ in range(world)]
    grads = [torch.empty_like(padded_grad) for _ in range(world)]
    dist.all_gather(indices, padded_index)
    dist.all_gather(grads, padded_grad)
    n = [int(s.item()) for s in sizes]
    return (torch.cat([x[:k] for x, k in zip(indices, n, strict=True)]),
            torch.cat([x[:k] for x, k in zip(grads, n, strict=True)]) / world)
