"""How much the visual features say about where the objects are, beyond proprioception: a linear probe.

Targets: the oracle's object poses relative to the gripper (`frontend.oracle`; per object of interest, position m
and the rotation matrix's first two columns), replayed from the demonstrations' saved simulator states and
standardised. Inputs, on the frames whose images are fresh (demonstrations rendered every k-th step repeat their
features in between): proprioception (joints + gripper, 9); proprioception and the step index with their products and
squares (a second-order expansion: the gripper's pose is a nonlinear function of the joints, and the phase of the
episode predicts much of where the objects are); the visual features of a converted dataset (ResNet18 + PCA,
`predvla convert`); and the expansion with the visual features. Ridge regressions (scikit-learn, the penalty chosen by
inner cross-validation) are scored by R^2 on held-out demonstrations (5 folds grouped by demonstration); the
partial R^2 of vision, (SSE_expansion - SSE_both) / SSE_expansion, is the share of what proprioception and the
phase leave unexplained that the visual features explain. The result decides how to read the oracle experiment: error
regression can only steer with what the features carry.

Command (from the repository root):

  python -m research.oracle_probe --hdf5-root outputs/libero_object_table2/hdf5 --suite libero_object \\
      --dataset-root outputs/libero_object_table2/dataset_features --out results/oracle/probe

Replays every demonstration's saved simulator states (physics only, minutes for 500 demonstrations), then fits the
ridge regressions; writes OUT/probe.json and OUT/probe.md.
"""

import argparse
import json
import os
import shlex
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.constants import OBS_STATE
from sklearn.linear_model import RidgeCV
from sklearn.model_selection import GroupKFold, cross_val_predict
from sklearn.preprocessing import PolynomialFeatures, StandardScaler

from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.data.libero_hdf5 import LiberoDataError, scan_suites
from lerobot_predvla.frontend.oracle import POSE_DIM
from lerobot_predvla.sims.libero.oracle import suite_object_poses

COMMAND = "python -m research.oracle_probe"
FOLDS = 5
ALPHAS = np.logspace(-3, 4, 15)
POSE_PARTS = {"position": slice(0, 3), "orientation": slice(3, POSE_DIM)}


@dataclass
class ProbeResult:
    """Held-out R^2 per target group (`<object>.<position|orientation>`) and overall."""

    frames: int
    demonstrations: int
    objects: dict[str, list[str]]
    r2_proprio: dict[str, float]
    r2_proprio_phase_quadratic: dict[str, float]
    r2_vision: dict[str, float]
    r2_both: dict[str, float]
    partial_r2_vision: dict[str, float]


def probe_data(hdf5_root: Path, suite: str, dataset_root: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                         np.ndarray, dict[str, list[str]]]:
    """Fresh frames' proprioception, step index, visual features, standardised oracle poses, demonstration index,
    and the objects of interest per instruction.

    The dataset's episodes must be the hdf5 demonstrations in `predvla convert`'s order (file name, then demo
    number), as that command writes them.
    """
    refs = scan_suites(hdf5_root, [suite])
    dataset = LeRobotDataset(f"local/{Path(dataset_root).name}", root=dataset_root)
    if dataset.meta.total_episodes != len(refs):
        raise ValueError(f"{dataset_root}: {dataset.meta.total_episodes} episodes, but {hdf5_root}/{suite} has "
                         f"{len(refs)} demonstrations; give the dataset converted from those files.")
    table = dataset.hf_dataset.with_format("numpy")[:]
    episodes = np.asarray(table["episode_index"])
    poses, objects = suite_object_poses(suite, refs)
    states, steps, visions, targets, groups = [], [], [], [], []
    for index, ref in enumerate(refs):
        rows = np.flatnonzero(episodes == index)
        if len(rows) != ref.num_frames:
            raise ValueError(f"{dataset_root}: episode {index} has {len(rows)} frames, {ref.file} {ref.demo} has "
                             f"{ref.num_frames}; give the dataset converted from those files.")
        vision = np.stack(table[OBS_VISION_FEATURES][rows])
        fresh = np.r_[True, np.any(vision[1:] != vision[:-1], axis=1)]
        states.append(np.stack(table[OBS_STATE][rows])[fresh])
        steps.append(np.asarray(table["frame_index"][rows])[fresh])
        visions.append(vision[fresh])
        targets.append(poses[(ref.file, ref.demo)][fresh])
        groups.append(np.full(fresh.sum(), index))
    target = StandardScaler().fit_transform(np.concatenate(targets))
    return (np.concatenate(states), np.concatenate(steps).astype(np.float64), np.concatenate(visions), target,
            np.concatenate(groups), objects)


def _held_out_sse(x: np.ndarray, y: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Per target dimension, the sum of squared errors of ridge predictions on held-out demonstrations."""
    x = StandardScaler().fit_transform(x)
    predicted = cross_val_predict(RidgeCV(alphas=ALPHAS), x, y, groups=groups, cv=GroupKFold(FOLDS))
    return ((y - predicted) ** 2).sum(0)


def run_probe(hdf5_root: Path, suite: str, dataset_root: Path) -> ProbeResult:
    state, step, vision, target, groups, objects = probe_data(hdf5_root, suite, dataset_root)
    standardised = StandardScaler().fit_transform(np.column_stack([state, step]))
    expansion = PolynomialFeatures(degree=2, include_bias=False).fit_transform(standardised)
    sse = {
        "proprio": _held_out_sse(state, target, groups),
        "expansion": _held_out_sse(expansion, target, groups),
        "vision": _held_out_sse(vision, target, groups),
        "both": _held_out_sse(np.hstack([expansion, vision]), target, groups),
    }
    total = ((target - target.mean(0)) ** 2).sum(0)
    names = next(iter(objects.values()))
    labels = {f"object{k}.{part}": (k, cols) for k in range(len(names)) for part, cols in POSE_PARTS.items()}

    def score(errors: np.ndarray, reference: np.ndarray) -> dict[str, float]:
        out = {}
        for label, (k, cols) in labels.items():
            dims = np.arange(k * POSE_DIM, (k + 1) * POSE_DIM)[cols]
            out[label] = float(1 - errors[dims].sum() / reference[dims].sum())
        out["all"] = float(1 - errors.sum() / reference.sum())
        return out

    return ProbeResult(
        frames=len(target), demonstrations=len(np.unique(groups)), objects=objects,
        r2_proprio=score(sse["proprio"], total), r2_proprio_phase_quadratic=score(sse["expansion"], total),
        r2_vision=score(sse["vision"], total), r2_both=score(sse["both"], total),
        partial_r2_vision=score(sse["both"], sse["expansion"]),
    )


def write_report(result: ProbeResult, out: Path, command: str) -> None:
    """`probe.json` and `probe.md` in `out` (each written atomically)."""
    out.mkdir(parents=True, exist_ok=True)
    rows = [f"| {label} | {result.r2_proprio[label]:.3f} | {result.r2_proprio_phase_quadratic[label]:.3f} | "
            f"{result.r2_vision[label]:.3f} | {result.r2_both[label]:.3f} | {result.partial_r2_vision[label]:.3f} |"
            for label in result.r2_proprio]
    objects = "; ".join(f"{text}: {', '.join(names)}" for text, names in result.objects.items())
    markdown = "\n".join([
        "# Linear probe: object poses relative to the gripper from the front end's features",
        "",
        f"Held-out R^2 ({FOLDS} folds grouped by demonstration) of ridge regressions on {result.frames} fresh "
        f"frames of {result.demonstrations} demonstrations. Targets: the oracle's standardised poses (objectK = the "
        "K-th object of interest; orientation = the rotation matrix's first two columns). Inputs: proprioception "
        "(linear); proprioception and the step index to second order; the visual features; the second-order "
        "expansion with the visual features (both). Partial R^2 of vision: the share of what the second-order "
        "expansion leaves unexplained that the visual features explain.",
        "",
        "| target | proprioception | proprioception + phase, 2nd order | vision | both | partial R^2 of vision |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
        f"Objects of interest: {objects}.",
        "",
        f"Command: `{command}`",
        "",
    ])
    for name, text in (("probe.json", json.dumps(asdict(result), indent=2) + "\n"), ("probe.md", markdown)):
        tmp = out / f".{name}.tmp"
        tmp.write_text(text)
        os.replace(tmp, out / name)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hdf5-root", type=Path, required=True, help="Directory with <suite>/*_demo.hdf5.")
    parser.add_argument("--suite", default="libero_object")
    parser.add_argument("--dataset-root", type=Path, required=True,
                        help="The dataset `predvla convert` wrote from them (or its features-only copy).")
    parser.add_argument("--out", type=Path, required=True, help="Directory for probe.json and probe.md.")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(argv)
    try:
        result = run_probe(args.hdf5_root, args.suite, args.dataset_root)
    except (LiberoDataError, ValueError, FileNotFoundError) as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    write_report(result, args.out, f"{COMMAND} {shlex.join(argv)}")
    print((args.out / "probe.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
