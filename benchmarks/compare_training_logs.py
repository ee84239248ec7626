"""Training-loss curves of two `lerobot-train` runs on the same batches (same seed, same data), side by side.

Written to judge bfloat16 mixed precision (`--policy.use_amp=true`) against float32: each log line of lerobot-train
averages its terms over the `--log_freq` steps since the previous line, so line i is step (i + 1) * log_freq of a run
that was not resumed. The runs "agree within noise" when, for every logged term, the mean absolute difference between
the two curves over the last `--window` lines is at most the reference curve's own noise there: the standard
deviation of the differences between its consecutive lines over sqrt(2) (how much one 100-step average of the same run
scatters; differencing removes the trend of a curve that is still falling).

    python -m benchmarks.compare_training_logs REFERENCE.log CANDIDATE.log --labels fp32 bf16 --out DIR
"""

import argparse
import json
import re
from pathlib import Path

import numpy as np

from lerobot_predvla.utils.io import atomic_save_figure, atomic_write_json

TERMS = ("loss", "vision_error", "proprio_error", "action_nll", "complexity", "grdn", "updt_s")
LINE = re.compile(r"step:\S+ .*?loss:")


def parse_log(path: Path) -> dict[str, np.ndarray]:
    """Every term of every `step:` line of a lerobot-train log, in order."""
    rows = []
    for line in Path(path).read_text(errors="replace").splitlines():
        if not LINE.search(line):
            continue
        fields = dict(re.findall(r"(\w+):([-+0-9.eE]+)(?=\s|$)", line[line.index("step:"):]))
        rows.append({k: float(fields[k]) for k in TERMS if k in fields})
    if not rows:
        raise ValueError(f"{path}: no lerobot-train log lines ('step:... loss:...') found.")
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def agreement(reference: np.ndarray, candidate: np.ndarray, window: int) -> dict[str, float]:
    ref, cand = reference[-window:], candidate[-window:]
    noise = float(np.diff(ref).std(ddof=1) / np.sqrt(2)) if len(ref) > 2 else float("nan")
    difference = float(np.abs(cand - ref).mean())
    return {"mean_abs_difference": difference, "reference_noise": noise,
            "relative_difference": difference / float(np.abs(ref).mean()), "agree": difference <= noise}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reference", type=Path)
    parser.add_argument("candidate", type=Path)
    parser.add_argument("--labels", nargs=2, default=["fp32", "bf16"])
    parser.add_argument("--log-freq", type=int, default=100)
    parser.add_argument("--window", type=int, default=10, help="log lines compared at the end of the runs")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    runs = [parse_log(args.reference), parse_log(args.candidate)]
    n = min(len(runs[0]["loss"]), len(runs[1]["loss"]))
    steps = (np.arange(n) + 1) * args.log_freq
    terms = [k for k in TERMS if k in runs[0] and k in runs[1]]
    report = {"steps": int(steps[-1]), "labels": args.labels, "window_lines": args.window,
              "update_s_median": {label: float(np.median(r["updt_s"][:n]))
                                  for label, r in zip(args.labels, runs, strict=True) if "updt_s" in r},
              "terms": {k: agreement(runs[0][k][:n], runs[1][k][:n], args.window) for k in terms if k != "updt_s"}}
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / "curves.json", report)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [k for k in terms if k not in ("updt_s", "grdn")]
    fig, axes = plt.subplots(1, len(shown), figsize=(3.2 * len(shown), 3))
    for ax, key in zip(np.atleast_1d(axes), shown, strict=True):
        for label, run in zip(args.labels, runs, strict=True):
            ax.plot(steps, run[key][:n], lw=1, label=label)
        ax.set(title=key, xlabel="training step", yscale="log" if key == "complexity" else "linear")
        ax.title.set_fontsize(9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_save_figure(fig, args.out / "curves.png", dpi=100)
    for key, row in report["terms"].items():
        print(f"{key:>14}: mean |{args.labels[1]} - {args.labels[0]}| {row['mean_abs_difference']:.4g} "
              f"({row['relative_difference']:.2%}) vs noise {row['reference_noise']:.4g}: "
              f"{'agree' if row['agree'] else 'DIFFER'}")
    print(json.dumps(report["update_s_median"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
