"""Acting on shared CPU cores: a control step of the shipped checkpoint at batch 2, on one thread and on torch's
default thread count, on the cores as they are and with a busy loop on every core.

One control step is what `lerobot-eval` runs per environment step for the policy: raw frames and state through the
checkpoint's saved preprocessor (the front end encodes on refresh ticks), `select_action`, the postprocessor. On the
CPU the plugin acts on one thread unless OMP_NUM_THREADS is set (`lerobot_predvla/utils/threads.py`): the "one
thread" arm runs the default path, the "default threads" arm sets OMP_NUM_THREADS to torch's default count (what
acting cost without the plugin's choice). Each arm is a fresh process timing `--steps` control steps after
`--warmup`; the loaded arms start one `python -c 'while True: pass'` per core first and end them afterwards.
Keys: `acting_ms_b2_{one_thread,default_threads}[_busy]` (medians) and the ratios
`acting_default_over_one_thread_busy` (the slowdown the plugin's choice avoids under load),
`acting_default_over_one_thread` (the same on the cores as they are) and `acting_busy_over_idle_one_thread`.

    python -m benchmarks.bench_acting_threads --steps 40
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import torch

from benchmarks.bench_control_rate import raw_frames

TASK = "pick up the alphabet soup and place it in the basket"


def control_steps_ms(checkpoint: Path, batch: int, steps: int, warmup: int) -> list[float]:
    """Times (ms) of `steps` control steps at `batch` after `warmup` ones, one fresh episode, on the CPU."""
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.policies.utils import prepare_observation_for_inference

    from lerobot_predvla import PredVLAConfig, PredVLAPolicy
    from lerobot_predvla.frontend.processor_step import FrontendProcessorStep

    config = PredVLAConfig.from_pretrained(checkpoint, cli_overrides=["--device=cpu"])
    policy = PredVLAPolicy.from_pretrained(checkpoint, config=config).eval()
    pre, post = make_pre_post_processors(config, pretrained_path=str(checkpoint),
                                         preprocessor_overrides={"device_processor": {"device": "cpu"}})
    cameras = next(list(s.artefact["vision"]["cameras"]) for s in pre.steps if isinstance(s, FrontendProcessorStep))
    frames = raw_frames(cameras, config.proprio_dim, (warmup + steps) * batch, 128)
    policy.reset()
    pre.reset()
    times = []
    for i in range(warmup + steps):
        rows = [prepare_observation_for_inference(dict(f), torch.device("cpu"), TASK, "bench")
                for f in frames[i * batch:(i + 1) * batch]]
        observation = {k: torch.cat([r[k] for r in rows]) for k in rows[0] if isinstance(rows[0][k], torch.Tensor)}
        observation["task"] = [TASK] * batch
        start = time.perf_counter()
        with torch.inference_mode():
            post(policy.select_action(pre(observation)))
        if i >= warmup:
            times.append(1e3 * (time.perf_counter() - start))
    return times


def arm(args: argparse.Namespace, threads: int | None, busy: bool) -> dict:
    """One fresh process: OMP_NUM_THREADS=threads (None: unset, the plugin's one thread), optionally busy cores."""
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    if threads is not None:
        env["OMP_NUM_THREADS"] = str(threads)
    loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() if busy else 0)]
    try:
        out = subprocess.run([sys.executable, "-m", "benchmarks.bench_acting_threads", "--worker", "--checkpoint",
                              str(args.checkpoint), "--batch", str(args.batch), "--steps", str(args.steps),
                              "--warmup", str(args.warmup)], env=env, check=True, capture_output=True, text=True)
    finally:
        for loop in loops:
            loop.kill()
            loop.wait()
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=Path("checkpoints/predvla_libero_object"))
    parser.add_argument("--batch", type=int, default=2)
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        times = control_steps_ms(args.checkpoint, args.batch, args.steps, args.warmup)
        print(json.dumps({"median_ms": statistics.median(times), "threads": torch.get_num_threads(), "times": times}))
        return
    default = torch.get_num_threads()
    results = {"cpus": os.cpu_count(), "default_threads": default, "batch": args.batch, "steps": args.steps}
    for busy in (False, True):
        suffix = "_busy" if busy else ""
        for name, threads in (("one_thread", None), ("default_threads", default)):
            results[f"acting_ms_b{args.batch}_{name}{suffix}"] = round(arm(args, threads, busy)["median_ms"], 1)
    ms = {key.removeprefix(f"acting_ms_b{args.batch}_"): v for key, v in results.items() if key.startswith("acting")}
    results.update(
        acting_default_over_one_thread=round(ms["default_threads"] / ms["one_thread"], 2),
        acting_default_over_one_thread_busy=round(ms["default_threads_busy"] / ms["one_thread_busy"], 2),
        acting_busy_over_idle_one_thread=round(ms["one_thread_busy"] / ms["one_thread"], 2),
    )
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
