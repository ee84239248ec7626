"""`predvla bench`: speed of the recurrent core, eager reference vs fused fast path vs matmul-only floor.

Runs `benchmarks/bench_core.py` from the repository checkout (editable install): prints a table of medians
and ratios, and as its last line one JSON object with every figure. `eval_peak_rss_gb` is the peak RSS (GB, 1e9
bytes) of one `lerobot-eval` of the shipped libero_object checkpoint at `--eval.batch_size=10`, 20-step episodes of
task 0, sync environments (`benchmarks/bench_eval_memory.py`; 8 min on heavily loaded cores, less on idle ones);
null, with the reason in `eval_peak_rss`, where the simulator is not installed.
"""

import argparse
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[2]


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("bench", help="time the recurrent core (training step, error regression)",
                                   description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer repeats (about a minute)")
    parser.add_argument("--threads", type=int, default=1, help="torch.set_num_threads (default 1)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not (REPOSITORY / "benchmarks" / "bench_core.py").exists():
        print("predvla bench needs the repository checkout (pip install -e .): benchmarks/ not found.")
        return 1
    sys.path.insert(0, str(REPOSITORY))
    from benchmarks import bench_core

    return bench_core.run(args)
