"""Feature-caching speed of the front end: batched bf16 channels-last vs plain per-frame fp32.

A batched fp32 channels-last path is measured too. All paths encode the same LIBERO-sized frames (two
128 x 128 cameras per frame, preprocessing included) in the same run; the script prints median frames/s
over repeats and how far the fast path's features are from the per-frame fp32 ones (raw 512-d and after a
96-component PCA fitted on the fp32 features).

    python benchmarks/bench_frontend.py --frames 128 --repeats 3 --vision-weights random
"""

import argparse
import statistics
import time

import numpy as np
import torch

from lerobot_predvla.frontend.pca import fit_pca
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec, libero_hdf5_to_lerobot, preprocess_images
from lerobot_predvla.frontend.vision import VisionEncoder, VisionWeights


def synthetic_frames(num_frames: int, seed: int) -> np.ndarray:
    """Smooth raw-orientation uint8 frames (N, 128, 128, 3) with moving blocks."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:128, 0:128] / 128
    frames = np.repeat((np.stack([xx, yy, 1 - xx * yy], -1) * 200)[None], num_frames, axis=0)
    for t in range(num_frames):
        y, x = rng.integers(0, 100, 2)
        frames[t, y : y + 28, x : x + 28] = rng.uniform(0, 255, 3)
    return frames.astype(np.uint8)


def encode(encoder: VisionEncoder, cameras: list[np.ndarray], spec: PreprocessingSpec, per_frame: bool):
    """Features of every camera; `per_frame` feeds one image at a time."""
    out = []
    for raw in cameras:
        chunks = [raw[i : i + 1] for i in range(len(raw))] if per_frame else [raw]
        out.append(torch.cat([encoder(preprocess_images(libero_hdf5_to_lerobot(c), spec)) for c in chunks]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=128, help="Frames (each two cameras) per repeat.")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--vision-weights", default="random", help="imagenet | PATH.pth | random")
    parser.add_argument("--threads", type=int, default=torch.get_num_threads())
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    spec = PreprocessingSpec()
    weights = VisionWeights.parse(args.vision_weights)
    fast = VisionEncoder(weights, "bf16", channels_last=True, batch_size=args.batch_size)
    batched_fp32 = VisionEncoder(weights, "fp32", channels_last=True, batch_size=args.batch_size, verbose=False)
    plain = VisionEncoder(weights, "fp32", channels_last=False, batch_size=1, verbose=False)
    cameras = [synthetic_frames(args.frames, seed) for seed in (0, 1)]
    encode(fast, [c[:8] for c in cameras], spec, per_frame=False)  # Warm-up (oneDNN kernel selection).
    encode(plain, [c[:2] for c in cameras], spec, per_frame=True)

    paths = {
        "fast (batched bf16 channels_last)": (fast, False),
        "batched fp32 channels_last": (batched_fp32, False),
        "plain (per-frame fp32)": (plain, True),
    }
    rates = {name: [] for name in paths}
    features = {}
    for _ in range(args.repeats):
        for name, (encoder, per_frame) in paths.items():
            start = time.perf_counter()
            features[name] = encode(encoder, cameras, spec, per_frame)
            rates[name].append(args.frames / (time.perf_counter() - start))

    print(f"{args.frames} frames x 2 cameras at 128 px, {args.repeats} repeats, {torch.get_num_threads()} threads, "
          f"weights: {weights.describe()}")
    for name, values in rates.items():
        print(f"  {name:36s} median {statistics.median(values):7.1f} frames/s  (all: "
              + ", ".join(f"{v:.1f}" for v in values) + ")")
    medians = [statistics.median(v) for v in rates.values()]
    print(f"  speed-up over plain: fast x{medians[0] / medians[2]:.2f}, batched fp32 x{medians[1] / medians[2]:.2f}")
    reference, candidate = features["plain (per-frame fp32)"], features["fast (batched bf16 channels_last)"]
    for cam, (ref, cand) in enumerate(zip(reference, candidate, strict=True)):
        basis = fit_pca(ref.numpy(), min(96, args.frames - 1))
        raw_dev = (cand - ref).norm(dim=1) / ref.norm(dim=1)
        pca_ref, pca_cand = basis.transform(ref), basis.transform(cand)
        pca_dev = (pca_cand - pca_ref).norm(dim=1) / pca_ref.norm(dim=1)
        print(f"  camera {cam}: bf16 vs fp32 relative L2 deviation, 512-d median {raw_dev.median():.4f} max "
              f"{raw_dev.max():.4f}; PCA-{basis.n_components} median {pca_dev.median():.4f} max {pca_dev.max():.4f}")


if __name__ == "__main__":
    main()
