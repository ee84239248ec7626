"""Control rate of PredVLA at batch 1: ticks per second a robot loop sustains, with and without a deadline.

One tick is what `lerobot-rollout`'s sync inference runs: raw frames and state through the checkpoint's saved
preprocessor (the front end encodes on refresh ticks only), `select_action`, the postprocessor. Each setting runs
`--warmup` ticks first (the error-regression window fills up to W = 40 steps) and is then timed over `--ticks`
ticks; the script prints median and p90 tick times, sustained ticks per second and the iterations error
regression ran, for the full `er_iterations` and for deadlines set from control rates (`--rates`, the tick period
minus the mean time of the tick's other work, front end included, measured in the same run).

    python benchmarks/bench_control_rate.py --checkpoint checkpoints/predvla_libero_object --rates 30 10
"""

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
import torch
from lerobot.policies.factory import make_pre_post_processors
from lerobot.policies.utils import prepare_observation_for_inference

from lerobot_predvla import PredVLAConfig, PredVLAPolicy
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep
from lerobot_predvla.policies.predvla.error_regression import IterationCounts


def raw_frames(cameras: list[str], state_dim: int, ticks: int, size: int, seed: int = 0) -> list[dict]:
    """Camera-like uint8 (size, size, 3) frames and a state vector per tick."""
    rng = np.random.default_rng(seed)
    return [{**{key: rng.integers(0, 256, (size, size, 3), dtype=np.uint8) for key in cameras},
             "observation.state": rng.normal(size=state_dim).astype(np.float32)} for _ in range(ticks)]


def run(checkpoint: Path, frames: list[dict], task: str, warmup: int, **overrides) -> dict:
    """Tick times (s) after `warmup` ticks and error regression's iteration counts, one fresh episode."""
    config = PredVLAConfig.from_pretrained(checkpoint, cli_overrides=[f"--{k}={v}" for k, v in overrides.items()])
    policy = PredVLAPolicy.from_pretrained(checkpoint, config=config).eval()
    device = torch.device(config.device)  # the best available: shipped configs leave the device unset
    pre, post = make_pre_post_processors(config, pretrained_path=str(checkpoint),
                                         preprocessor_overrides={"device_processor": {"device": config.device}})
    for step in pre.steps:
        if isinstance(step, FrontendProcessorStep):
            step.refresh_interval = config.visual_refresh_interval  # as saved by checkpoints written from now on
    policy.reset()
    pre.reset()
    times, er_times = [], []
    for i, frame in enumerate(frames):
        start = time.perf_counter()
        with torch.inference_mode():
            observation = prepare_observation_for_inference(dict(frame), device, task, "bench")
            batch = pre(observation)
            er_start = time.perf_counter()
            action = policy.select_action(batch)
            er_end = time.perf_counter()
            post(action)
        if i == warmup - 1:
            policy.error_regression.iterations = IterationCounts()  # count the timed ticks only
        if i >= warmup:
            times.append(time.perf_counter() - start)
            er_times.append(er_end - er_start)
    counts = policy.error_regression.iterations
    return {"tick_ms_median": 1e3 * statistics.median(times),
            "tick_ms_p90": 1e3 * float(np.percentile(times, 90)),
            "ticks_per_s": len(times) / sum(times),
            "error_regression_ms_median": 1e3 * statistics.median(er_times),
            "other_ms_mean": 1e3 * statistics.fmean(t - e for t, e in zip(times, er_times, strict=True)),
            "iterations_mean": counts.total / max(counts.steps, 1), "iterations_min": counts.fewest,
            "iterations_max": counts.most, "er_deadline_ms": overrides.get("er_deadline_ms")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=Path("checkpoints/predvla_libero_object"))
    parser.add_argument("--rates", type=float, nargs="+", default=[30.0, 10.0], help="Control rates (Hz).")
    parser.add_argument("--ticks", type=int, default=60)
    parser.add_argument("--warmup", type=int, default=40)
    parser.add_argument("--image-size", type=int, default=128)
    parser.add_argument("--backend", default=None, help="recurrence_backend override (python | cpp | auto)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--task", default="pick up the alphabet soup and place it in the basket")
    parser.add_argument("--out", type=Path, default=None, help="Write the results as JSON here too.")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    config = PredVLAConfig.from_pretrained(args.checkpoint)
    pre, _ = make_pre_post_processors(config, pretrained_path=str(args.checkpoint))
    cameras = next(list(s.artefact["vision"]["cameras"]) for s in pre.steps if isinstance(s, FrontendProcessorStep))
    frames = raw_frames(cameras, config.proprio_dim, args.warmup + args.ticks, args.image_size)
    base = {} if args.backend is None else {"recurrence_backend": args.backend}
    results = {"full": run(args.checkpoint, frames, args.task, args.warmup, **base)}
    other = results["full"]["other_ms_mean"]
    for rate in args.rates:
        deadline = round(1000.0 / rate - other, 1)
        results[f"{rate:g}Hz"] = run(args.checkpoint, frames, args.task, args.warmup, er_deadline_ms=max(deadline, 0.1),
                                     **base)
    report = {"threads": args.threads, "ticks": args.ticks, "warmup": args.warmup, "backend": args.backend,
              "results": results}
    print(json.dumps(report, indent=2))
    if args.out is not None:
        args.out.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
