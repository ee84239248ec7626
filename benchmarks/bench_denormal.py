"""Training step with a trained checkpoint's weights, subnormal floats kept against flushed (`flush_denormal`,
docs/speed.md).

Late in training some weights decay below 1.2e-38; the shipped Table 2 checkpoint (30,000 steps) holds about 1,200.
Its weights are loaded into the benchmark's model (`benchmarks.bench_core`: batch 16 x 150 steps, one thread) and the
two settings alternate on the same model and batch; medians of each.

  OMP_NUM_THREADS=1 python -m benchmarks.bench_denormal [--checkpoint DIR] [--repeats 5]
"""

import argparse
import json
from pathlib import Path

import torch
from safetensors.torch import load_file

from benchmarks.bench_core import interleaved_median_ms, randomised_model, train_step_fn, training_data
from lerobot_predvla import PredVLAConfig

CHECKPOINT = Path("checkpoints/predvla_libero_object_table2")


def flushed(step, flush: bool):
    def run() -> float:
        torch.set_flush_denormal(flush)
        return step()

    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=CHECKPOINT, help="a PredVLA pretrained_model directory")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    config = PredVLAConfig(device="cpu", flush_denormal=False)
    model = randomised_model(config)
    weights = load_file(str(args.checkpoint / "model.safetensors"))
    model.load_state_dict({k.removeprefix("model."): v for k, v in weights.items()})
    tiny = torch.finfo(torch.float32).tiny
    subnormal = sum(int(((p != 0) & (p.abs() < tiny)).sum()) for p in model.parameters())
    step = train_step_fn(model, model.rollout, training_data(config, 16, 150))
    times = interleaved_median_ms({"kept": flushed(step, False), "flushed": flushed(step, True)}, args.repeats)
    torch.set_flush_denormal(False)
    result = {"subnormal_weights": subnormal, **{f"train_step_ms_{k}": round(v[0], 1) for k, v in times.items()}}
    result["kept_over_flushed"] = round(result["train_step_ms_kept"] / result["train_step_ms_flushed"], 2)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
