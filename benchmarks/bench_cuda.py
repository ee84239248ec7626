"""The recurrent core on a CUDA device against the same machine's CPU, in one process.

Table 2's training step (batch 32, sequence length 200: forward, backward, gradient clip, network Adam, the
posteriors' row-wise Adam), in float32 and under bfloat16 autocast, and one error-regression control step
(Section 3.5: window 40, 10 iterations, then the action) at batch 1 and 10. Each is timed on the GPU (the Python
loops: the compiled loops are CPU only) and on the CPU with every core (`recurrence_backend="auto"`), on copies of
the same weights and data. Ratios are CPU over GPU; `table2_training_h` is 30,000 GPU steps at the median step.

    python -m benchmarks.bench_cuda [--quick]
"""

import argparse
import json
from collections.abc import Callable

import torch

from benchmarks.bench_core import (
    bf16_step_fn,
    control_step_fn,
    median_ms,
    randomised_model,
    train_step_fn,
    training_data,
)
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.sweep import PAPER_BATCH_SIZE, PAPER_TRAIN_STEPS


def synchronised(fn: Callable, device: str) -> Callable[[], None]:
    """`fn` followed by waiting for the device, so that a timer measures the work and not its launch."""
    if device != "cuda":
        return fn

    def call() -> None:
        fn()
        torch.cuda.synchronize()

    return call


def run_benchmark(quick: bool = False, steps: int = 200) -> dict:
    if not torch.cuda.is_available():
        raise SystemExit("bench_cuda needs a CUDA device (torch.cuda.is_available() is False).")
    repeats = 5 if quick else 20
    results: dict = {"gpu": torch.cuda.get_device_name(), "cpu_threads": torch.get_num_threads(),
                     "batch": PAPER_BATCH_SIZE, "steps": steps}
    for device in ("cuda", "cpu"):
        backend = "python" if device == "cuda" else "auto"
        config = PredVLAConfig(device=device, recurrence_backend=backend)
        data = training_data(config, PAPER_BATCH_SIZE, steps, device=device)
        for precision in ("fp32", "bf16"):
            model = randomised_model(config).to(device)
            step = train_step_fn(model, model.rollout, data)
            if precision == "bf16":
                step = bf16_step_fn(step, device)
            results[f"train_step_ms_{device}_{precision}"] = median_ms(synchronised(step, device), repeats, 2)[0]
        model = randomised_model(config).to(device)
        for batch in (1, 10):
            control = synchronised(control_step_fn(model, model.rollout, batch), device)
            results[f"er_ms_{device}_b{batch}"] = median_ms(control, repeats, 2)[0]
    for key in ("train_step_ms_{}_fp32", "train_step_ms_{}_bf16", "er_ms_{}_b1", "er_ms_{}_b10"):
        results[key.format("cpu_over_cuda")] = results[key.format("cpu")] / results[key.format("cuda")]
    results["table2_training_h"] = PAPER_TRAIN_STEPS * results["train_step_ms_cuda_fp32"] / 3.6e6
    print(f"PredVLA recurrent core on {results['gpu']} and on the CPU ({results['cpu_threads']} threads), "
          f"medians over {repeats} repeats (ms):")
    print(f"  {'':42s} {'GPU':>9s} {'CPU':>9s} {'CPU/GPU':>8s}")
    for label, key in ((f"training step B={PAPER_BATCH_SIZE} T={steps}, fp32", "train_step_ms_{}_fp32"),
                       (f"training step B={PAPER_BATCH_SIZE} T={steps}, bf16 autocast", "train_step_ms_{}_bf16"),
                       ("error regression control step b1", "er_ms_{}_b1"),
                       ("error regression control step b10", "er_ms_{}_b10")):
        print(f"  {label:42s} {results[key.format('cuda')]:9.1f} {results[key.format('cpu')]:9.1f} "
              f"{results[key.format('cpu_over_cuda')]:8.2f}")
    print(f"  Table 2's {PAPER_TRAIN_STEPS:,} training steps on the GPU at the fp32 median: "
          f"{results['table2_training_h']:.2f} h (the recurrent core alone; data loading not counted)")
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="5 repeats instead of 20")
    results = run_benchmark(quick=parser.parse_args(argv).quick)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
