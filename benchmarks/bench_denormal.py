"""Training step with a trained checkpoint, subnormal floats kept against flushed (`flush_denormal`, docs/speed.md).

Late in training some weights decay below 1.2e-38 (the shipped Table 2 checkpoint holds about 1,200), and the
gradients of a trained model on its own data hold many more. Two measurements, each alternating the two settings
on the same model and batch (medians of each):

- synthetic (default): the checkpoint's weights in the benchmark's model (`benchmarks.bench_core`: batch 16 x 150
  random steps, one thread), with a full optimisation step;
- `--dataset-root`: a training checkpoint (its `pretrained_model/` beside `training_state/`) on the dataset it was
  trained on, as `lerobot-train --resume` builds it (`make_policy`: weights, posterior store, cached episodes);
  `PredVLAPolicy.forward` and backward on `--batch` episodes drawn with seed 0. No optimizer step is taken, so both
  settings see the same weights, posteriors and batch. It also counts the subnormal gradients of one such step,
  and the subnormal values each operator outputs in it (`TorchDispatchMode`; views and allocations left out; the
  compiled recurrence's loops count as one operator each).

  OMP_NUM_THREADS=1 python -m benchmarks.bench_denormal [--checkpoint DIR] [--repeats 5]
  OMP_NUM_THREADS=1 python -m benchmarks.bench_denormal --checkpoint RUN/checkpoints/008000/pretrained_model \\
      --dataset-root DATASET [--batch 16] [--repeats 5]
"""

import argparse
import json
from collections.abc import Callable, Iterable
from pathlib import Path

import torch
from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
from lerobot.policies import make_policy
from lerobot.utils.constants import TRAINING_STATE_DIR
from safetensors.torch import load_file
from torch import Tensor
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from benchmarks.bench_core import interleaved_median_ms, randomised_model, train_step_fn, training_data
from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy

CHECKPOINT = Path("checkpoints/predvla_libero_object_table2")
UNINITIALISED = (torch.ops.aten.empty, torch.ops.aten.empty_like, torch.ops.aten.empty_strided,
                 torch.ops.aten.new_empty, torch.ops.aten.new_empty_strided)


def subnormal_count(tensors: Iterable[Tensor | None]) -> int:
    """Non-zero values below float32's smallest normal number (1.2e-38)."""
    tiny = torch.finfo(torch.float32).tiny
    return sum(int(((t != 0) & (t.abs() < tiny)).sum()) for t in tensors if t is not None)


class SubnormalRecorder(TorchDispatchMode):
    """Counts, per operator, the subnormal float32 values among the outputs of every call issued while active."""

    def __init__(self):
        super().__init__()
        self.counts: dict[str, int] = {}

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        if func.is_view or func.overloadpacket in UNINITIALISED:
            return out  # a view repeats its base's values; an allocation holds whatever memory it got
        tensors = [t for t in tree_leaves(out) if isinstance(t, Tensor) and t.dtype == torch.float32]
        found = subnormal_count(tensors)
        if found:
            name = str(func.overloadpacket)
            self.counts[name] = self.counts.get(name, 0) + found
        return out


def flushed(step: Callable[[], object], flush: bool) -> Callable[[], object]:
    def run() -> object:
        torch.set_flush_denormal(flush)
        return step()

    return run


def synthetic_step(checkpoint: Path) -> tuple[Callable[[], float], dict]:
    """A full optimisation step of the benchmark's model with the checkpoint's weights on a random batch."""
    config = PredVLAConfig(device="cpu", flush_denormal=False)
    model = randomised_model(config)
    weights = load_file(str(checkpoint / "model.safetensors"))
    model.load_state_dict({k.removeprefix("model."): v for k, v in weights.items()})
    step = train_step_fn(model, model.rollout, training_data(config, 16, 150))
    return step, {"subnormal_weights": subnormal_count(model.parameters())}


def dataset_step(checkpoint: Path, dataset_root: Path, batch: int) -> tuple[Callable[[], None], dict]:
    """Forward and backward of the resumed policy on `batch` of its own training episodes (no optimizer step)."""
    if not (checkpoint.parent / TRAINING_STATE_DIR).is_dir():
        raise SystemExit(f"--checkpoint {checkpoint}: not a training checkpoint (no ../training_state beside it); "
                         "--dataset-root needs the posterior store that lerobot-train saves there.")
    config = PredVLAConfig.from_pretrained(checkpoint, cli_overrides=["--flush_denormal=false"])
    config.pretrained_path = checkpoint
    policy: PredVLAPolicy = make_policy(config, ds_meta=LeRobotDatasetMetadata("local/bench", root=dataset_root))
    policy.train()
    g = torch.Generator().manual_seed(0)
    episodes = {"episode_index": torch.randint(policy.posterior_store.num_episodes, (batch,), generator=g)}

    def step() -> None:
        policy.zero_grad(set_to_none=True)
        policy.posterior_store.discard_pending()
        loss, _ = policy.forward(episodes)
        loss.backward()

    torch.set_flush_denormal(False)
    recorder = SubnormalRecorder()
    with recorder:
        step()
    posterior_grads = [rows.grad for _, rows in policy.posterior_store.pending_gradients()]
    counts = {
        "subnormal_weights": subnormal_count(policy.network_parameters()),
        "subnormal_weight_grads": subnormal_count(p.grad for p in policy.network_parameters()),
        "subnormal_posterior_grads": subnormal_count(posterior_grads),
        "subnormal_matmul_outputs": sum(recorder.counts.get(op, 0) for op in ("aten.mm", "aten.addmm", "aten.bmm")),
        "subnormal_op_outputs": dict(sorted(recorder.counts.items(), key=lambda kv: -kv[1])[:8]),
    }
    return step, counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=CHECKPOINT, help="a PredVLA pretrained_model directory")
    parser.add_argument("--dataset-root", type=Path, default=None,
                        help="the checkpoint's training dataset: time its own training step (see above)")
    parser.add_argument("--batch", type=int, default=16, help="episodes per step with --dataset-root")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.dataset_root is None:
        step, result = synthetic_step(args.checkpoint)
    else:
        step, result = dataset_step(args.checkpoint, args.dataset_root, args.batch)
    times = interleaved_median_ms({"kept": flushed(step, False), "flushed": flushed(step, True)}, args.repeats)
    torch.set_flush_denormal(False)
    result.update({f"train_step_ms_{k}": round(v[0], 1) for k, v in times.items()})
    result["kept_over_flushed"] = round(result["train_step_ms_kept"] / result["train_step_ms_flushed"], 2)
    print(json.dumps({"checkpoint": str(args.checkpoint), **result}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
