"""Speed of the recurrent core: eager reference vs fused fast path vs matmul-only floor, in one process.

Training step (Eq. 10, forward + backward + gradient clip + both Adam optimizers) and one error-regression
control step (Section 3.5: window W, n_itr iterations, full window). The floor replays, on random tensors of
the same shapes and strides, exactly the matmuls the fast path issued, and nothing else. "fast" is the default
configuration (`recurrence_backend="auto"`: the compiled loops where they build, `er_backend` says which ran). Error
regression is timed on that default path (`er_ms_fast_*`) and with the Python loops (`er_ms_python_*`,
`recurrence_backend="python"`), in alternation with their common floor (the two issue the same matmuls; checked).
The training step is also timed as `lerobot-train` takes it (`bench_lerobot_train.py`), in alternation with the
fast step at the same batch and sequence length. `control_step_ms_p50/_p99` time a whole control step at batch 1 on
the default path: the front end's ResNet18 on refresh steps, error regression, the action. `eval_peak_rss_gb` is the
peak RSS of one `lerobot-eval` of the shipped checkpoint at batch 10 (`bench_eval_memory.py`).

    python -m benchmarks.bench_core --quick
"""

import argparse
import dataclasses
import json
import statistics
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import torch
from torch import Tensor, nn
from torch.utils._python_dispatch import TorchDispatchMode

from benchmarks.bench_eval_memory import eval_peak_rss
from lerobot_predvla.policies.common.losses import masked_mean
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression
from lerobot_predvla.policies.predvla.modeling_predvla import training_complexity
from lerobot_predvla.policies.predvla.posterior_store import PosteriorStore
from lerobot_predvla.policies.predvla.predictive_model import PredictiveModel
from lerobot_predvla.policies.predvla.recurrence_cpp import loops, recurrence
from lerobot_predvla.policies.predvla.reference import reference_rollout

STORE_EPISODES = (100, 10_000)  # x 200 steps: 10,000 episodes is 2 GB of posteriors, 6 GB with Adam's moments
STORE_BATCH = 8
FRONTEND_DATASET = {True: (2, 50), False: (10, 200)}  # episodes x frames of the video dataset, --quick or not
CONTROL_STEPS = {True: 80, False: 400}  # control steps timed end to end, --quick or not (20 / 100 refreshes)
MATMULS = {torch.ops.aten.mm.default, torch.ops.aten.addmm.default, torch.ops.aten.bmm.default,
           torch.ops.aten.mm.out, torch.ops.aten.addmm.out}


def randomised_model(config: PredVLAConfig, seed: int = 0) -> PredictiveModel:
    """Default initialisation with non-zero biases and initial states, so that no pathway is silent."""
    torch.manual_seed(seed)
    model = PredictiveModel(config)
    with torch.no_grad():
        for p in model.parameters():
            if p.dim() == 1:
                p.normal_(0, 0.3)
    return model


def training_data(config: PredVLAConfig, batch: int, steps: int, seed: int = 0,
                  device: str = "cpu") -> dict[str, Tensor]:
    """A synthetic batch of whole episodes, time-major, every step valid (drawn on the CPU, the same on any device)."""
    g = torch.Generator().manual_seed(seed)
    data = {
        "language": torch.randn(batch, config.language_dim, generator=g),
        "vision": torch.randn(steps, batch, config.vision_dim, generator=g),
        "state": torch.randn(steps, batch, config.proprio_dim, generator=g),
        "action": torch.rand(steps, batch, config.action_dim, generator=g) * 1.8 - 0.9,
        "c_q": 0.3 * torch.randn(steps, batch, 4 * config.latent_dim, generator=g),
    }
    return {k: v.to(device) for k, v in data.items()}


def training_loss(model: PredictiveModel, rollout: Callable, data: dict[str, Tensor], c_q: Tensor) -> Tensor:
    """Eq. 10, as `PredVLAPolicy.forward` computes it, with the given rollout."""
    cfg = model.config
    traj = rollout(model.initial_state(c_q.shape[1]), model.language_term(data["language"]), c_q)
    steps = torch.arange(c_q.shape[0], device=c_q.device)[:, None].expand(c_q.shape[:2])
    valid = torch.ones(c_q.shape[:2], dtype=torch.bool, device=c_q.device)
    fresh = steps % cfg.visual_refresh_interval == 0
    eps_v, eps_q = model.prediction_errors(traj, data["vision"], data["state"])
    complexity = model.complexity(c_q, model.priors(traj), cfg.complexity_weights)
    return (
        cfg.lambda_v * masked_mean(eps_v, fresh) + cfg.lambda_q * masked_mean(eps_q, valid)
        + cfg.lambda_a * masked_mean(model.action_nll(traj, data["action"]), valid)
        + training_complexity(complexity, valid, cfg.complexity_reduction)
    )


def train_step_fn(model: PredictiveModel, rollout: Callable, data: dict[str, Tensor],
                  store: PosteriorStore | None = None) -> Callable[[], float]:
    """One optimisation step as `lerobot-train` takes it: forward, backward, gradient clip, network Adam, then the
    posteriors' row-wise Adam (`PredVLAPolicy.update`; Table 2). Without `store` the posteriors are the batch's
    own (`data["c_q"]`, every row in every batch); with one, those of random episodes of it."""
    cfg = model.config
    steps, batch, dim = data["c_q"].shape
    g = torch.Generator().manual_seed(0)
    if store is None:
        store = PosteriorStore(batch, steps, dim, lr=cfg.posterior_lr).to(data["c_q"].device)
        store.latents.copy_(data["c_q"].transpose(0, 1))
    whole_batch = store.num_episodes == batch
    network = torch.optim.Adam(model.parameters(), lr=cfg.optimizer_lr, weight_decay=cfg.optimizer_weight_decay)

    def step() -> float:
        network.zero_grad(set_to_none=True)
        episodes = torch.arange(batch) if whole_batch else torch.randint(store.num_episodes, (batch,), generator=g)
        episodes = episodes.to(store.latents.device)
        loss = training_loss(model, rollout, data, store.gather(episodes))
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip_norm)
        network.step()
        store.step()
        return loss.item()

    return step


def bf16_step_fn(step: Callable[[], float], device: str = "cpu") -> Callable[[], float]:
    """`step` under bfloat16 autocast, as `lerobot-train --policy.use_amp=true` takes it on `device` (the recurrence's
    loops and the heads in bfloat16, losses, posteriors and both Adams in float32)."""

    def bf16_step() -> float:
        with torch.autocast(device, dtype=torch.bfloat16):
            return step()

    return bf16_step


def control_stream(config: PredVLAConfig, batch: int, steps: int, seed: int = 0,
                   device: str = "cpu") -> tuple[Tensor, list]:
    g = torch.Generator().manual_seed(seed)
    language = torch.randn(batch, config.language_dim, generator=g).to(device)
    obs = [(torch.randn(batch, config.vision_dim, generator=g).to(device),
            torch.randn(batch, config.proprio_dim, generator=g).to(device)) for _ in range(steps)]
    return language, obs


def control_step_fn(model: PredictiveModel, rollout: Callable, batch: int, seed: int = 0) -> Callable[[], Tensor]:
    """One error-regression control step on a full window (filled with observe-only steps beforehand), on the
    model's device."""
    cfg = model.config
    device = next(model.parameters()).device
    language, obs = control_stream(cfg, batch, cfg.er_window + 64, seed, device)
    er = ErrorRegression(model, rollout)
    for vision, proprio in obs[: cfg.er_window]:
        er.observe(language, vision, proprio)
    stream = iter(obs[cfg.er_window :])
    return lambda: er(language, *next(stream))


def median_ms(fn: Callable, repeats: int, warmup: int = 1) -> tuple[float, list[float]]:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), times


def interleaved_median_ms(fns: dict[str, Callable], repeats: int, warmup: int = 1) -> dict[str, tuple[float, list]]:
    """Medians of functions timed in alternation, so that load from other work on shared cores weighs on each
    alike; warm-up calls excluded."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    times: dict[str, list[float]] = {key: [] for key in fns}
    for _ in range(repeats):
        for key, fn in fns.items():
            start = time.perf_counter()
            fn()
            times[key].append((time.perf_counter() - start) * 1e3)
    return {key: (statistics.median(t), t) for key, t in times.items()}


def lerobot_train_comparison(model: PredictiveModel, data: dict[str, Tensor], repeats: int) -> dict:
    """`lerobot-train`'s step (dataset batch, preprocessor, `update_policy`) and the fast step on the same batch
    size, sequence length, network weights and number of episodes in the posterior store, in alternation."""
    from benchmarks.bench_lerobot_train import lerobot_train_step_fn

    steps, batch, dim = data["c_q"].shape
    with tempfile.TemporaryDirectory() as tmp:
        lerobot_step, policy = lerobot_train_step_fn(Path(tmp), batch, steps, weights=model)
        store = PosteriorStore(policy.posterior_store.num_episodes, steps, dim, lr=model.config.posterior_lr)
        fast_step = train_step_fn(model, model.rollout, data, store)
        return interleaved_median_ms(
            {"lerobot_train_step_ms": lerobot_step, "train_step_ms_fast_same_shape": fast_step}, repeats
        )


class MatmulRecorder(TorchDispatchMode):
    """Records the shapes and strides of every matmul issued while active."""

    def __init__(self):
        super().__init__()
        self.calls: list[tuple] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func in MATMULS:
            operands = args[:3] if func in (torch.ops.aten.addmm.default, torch.ops.aten.addmm.out) else args[:2]
            self.calls.append((func.overloadpacket, tuple((x.shape, x.stride()) for x in operands)))
        return func(*args, **(kwargs or {}))


def recorded_matmuls(fn: Callable) -> list[tuple]:
    """The matmuls (op, operand shapes and strides) one call of `fn` issues, in order."""
    recorder = MatmulRecorder()
    with recorder:
        fn()
    return recorder.calls


def floor_fn(fn: Callable) -> tuple[Callable[[], None], int]:
    """A function issuing the same matmuls as one call of `fn`, on random operands, and nothing else."""
    recorded = recorded_matmuls(fn)
    operands: dict = {}

    def tensor(shape: torch.Size, stride: tuple[int, ...]) -> Tensor:
        key = (tuple(shape), stride)
        if key not in operands:
            operands[key] = torch.empty_strided(shape, stride).normal_()
        return operands[key]

    calls = [(op, [tensor(*spec) for spec in specs]) for op, specs in recorded]

    def replay() -> None:
        for op, args in calls:
            op(*args)

    return replay, len(calls)


def frontend_fn(frames: int) -> tuple[Callable[[int], Tensor], int]:
    """The front end at batch 1 as a control step runs it: ResNet18 features of frame t (two 128 px cameras,
    preprocessing included, random weights, fp32 channels-last: `predvla fit-frontend`'s default precision) and
    the number of frames available."""
    from benchmarks.bench_frontend import encode, synthetic_frames
    from lerobot_predvla.frontend.preprocessing import PreprocessingSpec
    from lerobot_predvla.frontend.vision import VisionEncoder, VisionWeights

    encoder = VisionEncoder(VisionWeights.parse("random"), "fp32", channels_last=True, batch_size=1, verbose=False)
    cameras = [synthetic_frames(frames, seed) for seed in (0, 1)]
    spec = PreprocessingSpec()
    return lambda t: torch.cat(encode(encoder, [c[t : t + 1] for c in cameras], spec, False), dim=-1), frames


def control_step_latencies_ms(model: PredictiveModel, steps: int) -> list[float]:
    """Wall time of `steps` whole control steps at batch 1 on the model's default path, error-regression window
    full: on every `visual_refresh_interval`-th step the front end encodes the new frame (its 1,024 ResNet18
    features projected to the policy's `vision_dim`, PCA's cost), between refreshes the last features are reused
    (what `FrontendProcessorStep` does); then error regression and the action."""
    cfg = model.config
    encode_frame, frames = frontend_fn(16)
    projection = torch.randn(encode_frame(0).shape[-1], cfg.vision_dim) / 32
    language, obs = control_stream(cfg, 1, cfg.er_window + steps)
    er = ErrorRegression(model)
    for vision, proprio in obs[: cfg.er_window]:
        er.observe(language, vision, proprio)
    er.infer()  # warm-up
    times, vision = [], None
    for t, (_, proprio) in enumerate(obs[cfg.er_window :]):
        start = time.perf_counter()
        if er.step_index % cfg.visual_refresh_interval == 0:
            vision = encode_frame(t % frames) @ projection
        er(language, vision, proprio)
        times.append((time.perf_counter() - start) * 1e3)
    return times


def frontend_dataset_rates(episodes: int, length: int) -> dict:
    """`predvla convert --dataset-root` end to end on a generated video dataset (two 128 px cameras), frames per
    second, with a front end fitted in fp32 (`predvla fit-frontend`'s default) and in bf16 (`--precision bf16`)."""
    from benchmarks.bench_frontend_dataset import frontend_throughput, make_video_dataset

    with tempfile.TemporaryDirectory() as tmp:
        root = make_video_dataset(Path(tmp) / "video_dataset", episodes, length)
        rates = {precision: frontend_throughput(Path(tmp), root, precision) for precision in ("fp32", "bf16")}
    return {"frontend_frames": rates["fp32"]["frames"],
            "frontend_frames_per_s": rates["fp32"]["convert_frames_per_s"],
            "frontend_frames_per_s_bf16": rates["bf16"]["convert_frames_per_s"],
            "frontend_fit_frames_per_s": rates["fp32"]["fit_frames_per_s"],
            "frontend_fit_frames_per_s_bf16": rates["bf16"]["fit_frames_per_s"]}


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (linear interpolation between order statistics)."""
    return statistics.quantiles(values, n=100, method="inclusive")[round(q) - 1]


def run_benchmark(quick: bool = False, threads: int = 1, batch: int = 32, steps: int = 200) -> dict:
    """Times every path, prints a table and returns the medians (ms) and ratios."""
    torch.set_num_threads(threads)
    config = PredVLAConfig(device="cpu")
    model = randomised_model(config)
    fast, ref = model.rollout, partial(reference_rollout, model)
    reps_ref, reps_fast = (1, 4) if quick else (5, 15)
    data = training_data(config, batch, steps)
    results, spread = {}, {}

    def record(key: str, fn: Callable, repeats: int, warmup: int = 1) -> None:
        results[key], spread[key] = median_ms(fn, repeats, warmup)

    record("train_step_ms_ref", train_step_fn(model, ref, data), reps_ref)
    fast_step = train_step_fn(model, fast, data)
    record("train_step_ms_fast", fast_step, reps_fast)
    replay, results["train_matmuls"] = floor_fn(fast_step)
    record("train_step_ms_floor", replay, reps_fast)
    # Mixed precision (`--policy.use_amp`, the CPU default): fp32 and bf16 steps in alternation, each with its own
    # copy of the same weights and posteriors, at Table 2's batch and sequence length.
    amp = {"train_step_ms_fp32": train_step_fn(randomised_model(config), fast, data),
           "train_step_ms_bf16": bf16_step_fn(train_step_fn(randomised_model(config), fast, data))}
    for key, (median, times) in interleaved_median_ms(amp, reps_fast, warmup=2).items():
        results[key], spread[key] = median, times
    record("er_ms_ref_b1", control_step_fn(model, ref, 1), reps_ref)
    # Error regression on the default path ("auto") and with the Python loops (same weights), timed in alternation
    # with their floor: both issue the same matmuls on the same operands (checked).
    python_model = randomised_model(dataclasses.replace(config, recurrence_backend="python"))
    for b in (1, 10):
        fast_control = control_step_fn(model, fast, b)
        python_control = control_step_fn(python_model, python_model.rollout, b)
        replay, results[f"er_matmuls_b{b}"] = floor_fn(fast_control)
        if recorded_matmuls(python_control) != recorded_matmuls(fast_control):
            raise RuntimeError("the compiled recurrence issues other matmuls than the Python one: no common floor")
        timed = {f"er_ms_fast_b{b}": fast_control, f"er_ms_python_b{b}": python_control, f"er_ms_floor_b{b}": replay}
        for key, (median, times) in interleaved_median_ms(timed, reps_fast, warmup=2).items():
            results[key], spread[key] = median, times
    results["er_backend"] = "cpp" if loops(config.recurrence_backend, data["c_q"]) is recurrence else "python"
    store_data = training_data(config, STORE_BATCH, steps)
    for episodes in STORE_EPISODES:  # per-step cost of the posterior store, small and LIBERO-90-sized datasets
        store = PosteriorStore(episodes, steps, store_data["c_q"].shape[-1], lr=config.posterior_lr)
        record(f"store_step_ms_{episodes}ep", train_step_fn(model, model.rollout, store_data, store), reps_fast)
    for key, (median, times) in lerobot_train_comparison(model, data, max(reps_fast, 5)).items():
        results[key], spread[key] = median, times
    encode_frame, _ = frontend_fn(1)
    results["frontend_ms_b1"] = median_ms(partial(encode_frame, 0), reps_fast, warmup=2)[0]
    latencies = control_step_latencies_ms(model, CONTROL_STEPS[quick])
    for q in (50, 99):
        results[f"control_step_ms_p{q}"] = percentile(latencies, q)
    results["control_steps"] = len(latencies)
    results.update(frontend_dataset_rates(*FRONTEND_DATASET[quick]))
    results.update(eval_peak_rss())  # one lerobot-eval at batch 10 (benchmarks/bench_eval_memory.py)

    results.update(
        threads=threads, batch=batch, steps=steps, window=config.er_window, er_iterations=config.er_iterations,
        train_speedup=results["train_step_ms_ref"] / results["train_step_ms_fast"],
        train_fast_over_floor=results["train_step_ms_fast"] / results["train_step_ms_floor"],
        train_bf16_over_fp32=results["train_step_ms_bf16"] / results["train_step_ms_fp32"],
        er_speedup_b1=results["er_ms_ref_b1"] / results["er_ms_fast_b1"],
        er_fast_over_floor_b1=results["er_ms_fast_b1"] / results["er_ms_floor_b1"],
        er_fast_over_floor_b10=results["er_ms_fast_b10"] / results["er_ms_floor_b10"],
        er_python_over_floor_b1=results["er_ms_python_b1"] / results["er_ms_floor_b1"],
        er_python_over_floor_b10=results["er_ms_python_b10"] / results["er_ms_floor_b10"],
        control_rate_hz_p50=1e3 / results["control_step_ms_p50"],
        store_10000_over_100=results["store_step_ms_10000ep"] / results["store_step_ms_100ep"],
        lerobot_train_over_fast=results["lerobot_train_step_ms"] / results["train_step_ms_fast_same_shape"],
    )
    print(f"PredVLA recurrent core, {threads} thread(s), medians over repeats (ms):")
    rows = [
        (f"training step B={batch} T={steps}", "train_step_ms"),
        (f"error regression b1 W={config.er_window} n_itr={config.er_iterations}", "er_ms", "_b1"),
        ("error regression b10", "er_ms", "_b10"),
    ]
    print(f"  {'':44s} {'reference':>10s} {'fast':>10s} {'floor':>10s} {'ref/fast':>9s} {'fast/floor':>10s}")
    for label, prefix, *suffix in rows:
        s = suffix[0] if suffix else ""
        r, f, fl = (results.get(f"{prefix}_{kind}{s}") for kind in ("ref", "fast", "floor"))
        cells = [f"{x:10.1f}" if x is not None else f"{'-':>10s}" for x in (r, f, fl)]
        ratio = f"{r / f:9.2f}" if r is not None else f"{'-':>9s}"
        print(f"  {label:44s} {' '.join(cells)} {ratio} {f / fl:10.2f}")
    print(f"  the fast rows ran the {results['er_backend']} loops (recurrence_backend='auto'); error regression with "
          f"the Python loops, b1 / b10: {results['er_ms_python_b1']:.1f} / {results['er_ms_python_b10']:.1f} ms, "
          f"over the floor {results['er_python_over_floor_b1']:.2f} / {results['er_python_over_floor_b10']:.2f}")
    print(f"  training step B={batch} T={steps} under bf16 autocast / fp32, in alternation: "
          f"{results['train_step_ms_bf16']:.1f} / {results['train_step_ms_fp32']:.1f} ms "
          f"(ratio {results['train_bf16_over_fp32']:.2f})")
    print(f"  control step b1 end to end over {results['control_steps']} steps (front end "
          f"{results['frontend_ms_b1']:.1f} ms on every {config.visual_refresh_interval}th, error regression, action): "
          f"p50 {results['control_step_ms_p50']:.1f} ms ({results['control_rate_hz_p50']:.1f} Hz), p99 "
          f"{results['control_step_ms_p99']:.1f} ms; paper: 46 ms on an RTX 5090")
    print(f"  predvla convert --dataset-root, {results['frontend_frames']} video frames x 2 cameras, end to end: "
          f"{results['frontend_frames_per_s']:.1f} frames/s (fp32 front end), "
          f"{results['frontend_frames_per_s_bf16']:.1f} (bf16); fit-frontend {results['frontend_fit_frames_per_s']:.1f}"
          f" / {results['frontend_fit_frames_per_s_bf16']:.1f}")
    print(f"  peak RSS of one lerobot-eval: {results['eval_peak_rss_gb']} GB ({results['eval_peak_rss']})")
    print(f"  training step B={STORE_BATCH} T={steps} with a posterior store of 100 / 10,000 episodes: "
          f"{results['store_step_ms_100ep']:.1f} / {results['store_step_ms_10000ep']:.1f} ms "
          f"(ratio {results['store_10000_over_100']:.2f})")
    print(f"  lerobot-train step B={batch} T={steps} (dataset batch, preprocessor, update_policy) / fast step, "
          f"timed in alternation: {results['lerobot_train_step_ms']:.1f} / "
          f"{results['train_step_ms_fast_same_shape']:.1f} ms (ratio {results['lerobot_train_over_fast']:.2f})")
    print("  all timings (ms): " + "; ".join(f"{k} " + ",".join(f"{v:.0f}" for v in vs) for k, vs in spread.items()))
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (under a minute)")
    parser.add_argument("--threads", type=int, default=1, help="torch.set_num_threads")
    return run(parser.parse_args(argv))


def run(args: argparse.Namespace) -> int:
    results = run_benchmark(quick=args.quick, threads=args.threads)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in results.items()}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
