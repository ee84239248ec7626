"""Skipping the padding (`modeling_predvla.trim_padding`) against running the recurrence over it, in one run.

Table 2 trains on sequences of 200 steps while libero_object's demonstrations are 132-150 steps long, so every batch
ends 50-68 steps before its padding does. The losses and every gradient are the same either way
(tests/test_policy.py); this measures the `lerobot-train` step (`bench_lerobot_train.py`) on a dataset with those
lengths, alternating steps with the padding skipped and run, and reports the medians and their ratio.

    python -m benchmarks.bench_trim_padding
"""

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import torch

from benchmarks.bench_lerobot_train import lerobot_train_step_fn
from lerobot_predvla.policies.predvla import modeling_predvla

SEQUENCE_LENGTH, EPISODE_LENGTHS = 200, (132, 150)  # Table 2's sequences; libero_object's demonstrations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--rounds", type=int, default=10, help="Paired rounds after one warm-up round.")
    args = parser.parse_args()
    torch.manual_seed(0)
    trimmed, padded = modeling_predvla.trim_padding, lambda seq, c_q: (seq, c_q)
    times: dict[str, list[float]] = {"trimmed": [], "padded": []}
    with tempfile.TemporaryDirectory() as tmp:
        step, _policy = lerobot_train_step_fn(Path(tmp), args.batch, SEQUENCE_LENGTH, lengths=EPISODE_LENGTHS)
        for round_index in range(args.rounds + 1):
            for name, trim in (("trimmed", trimmed), ("padded", padded)):
                modeling_predvla.trim_padding = trim
                start = time.perf_counter()
                step()
                if round_index > 0:
                    times[name].append((time.perf_counter() - start) * 1e3)
        modeling_predvla.trim_padding = trimmed
    medians = {f"step_ms_{name}": statistics.median(values) for name, values in times.items()}
    ratios = [t / p for t, p in zip(times["trimmed"], times["padded"], strict=True)]
    print(json.dumps({**medians, "trimmed_over_padded_median": statistics.median(ratios), "batch": args.batch,
                      "sequence_length": SEQUENCE_LENGTH, "episode_lengths": EPISODE_LENGTHS, "rounds": args.rounds},
                     indent=2))


if __name__ == "__main__":
    main()
