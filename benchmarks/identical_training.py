"""Whether two commits train bit-identical weights: the same fixed-seed `lerobot-train` run from a checkout of each.

Each commit is checked out as a temporary `git worktree` and trained with this environment's `lerobot-train`, its
code taken from the worktree (`PYTHONPATH`), for `--steps` steps of `--policy.type=predvla` on CPU, one thread, on
one small synthetic dataset (`predvla demo synthetic`'s, written once and read by both). The two
`model.safetensors` are then compared byte for byte. For a refactor that must not change training:

    python -m benchmarks.identical_training main            # main against HEAD
    python -m benchmarks.identical_training main main       # a commit against itself: the check's own noise

Prints both SHA-256 digests; exits 0 when they are equal, 1 when they differ.
"""

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from lerobot_predvla.data.synthetic import make_synthetic_dataset
from lerobot_predvla.utils.checkpoints import last_pretrained

REPO = Path(__file__).resolve().parents[1]
LEROBOT_TRAIN = str(Path(sys.executable).with_name("lerobot-train"))
WEIGHTS_FILE = "model.safetensors"


def train_command(dataset: Path, out: Path, steps: int, seed: int) -> list[str]:
    """`predvla demo synthetic`'s training, with a fixed seed and a single checkpoint at the last step."""
    return [
        LEROBOT_TRAIN,
        "--policy.type=predvla",
        "--dataset.repo_id=local/predvla_synthetic",
        f"--dataset.root={dataset}",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--num_workers=0",
        "--wandb.enable=false",
        f"--steps={steps}",
        "--batch_size=8",
        f"--save_freq={steps}",
        "--log_freq=50",
        "--policy.sequence_length=64",
        "--policy.optimizer_lr=1e-3",
        f"--seed={seed}",
        f"--output_dir={out}",
    ]


def training_env(code: Path) -> dict[str, str]:
    """The code of `code` ahead of the installed package; one thread, so that no reduction depends on the cores."""
    return {
        **os.environ,
        "PYTHONPATH": str(code),
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "HF_HUB_OFFLINE": "1",
    }


def check_code_location(code: Path) -> None:
    """Fail unless the plugin imports from `code`, not from the installed checkout."""
    probe = "import lerobot_predvla as a, lerobot_policy_predvla as b; print(a.__file__, b.__file__)"
    files = subprocess.run(
        [sys.executable, "-c", probe], env=training_env(code), cwd=code, check=True, capture_output=True, text=True
    ).stdout.split()
    if not all(Path(f).resolve().is_relative_to(code.resolve()) for f in files):
        raise RuntimeError(f"the plugin imports from {files}, not from the worktree {code}")


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def train_commit(commit: str, name: str, work: Path, dataset: Path, steps: int, seed: int) -> str:
    """Train `commit` from a temporary worktree under `work`; return the digest of its weights."""
    code = work / name
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "--quiet", str(code), commit], check=True)
    try:
        check_code_location(code)
        out = work / f"{name}_train"
        log = work / f"{name}_train.log"
        print(f"{name}: training {commit} ({steps} steps), log {log}", flush=True)
        with log.open("w") as handle:
            subprocess.run(
                train_command(dataset, out, steps, seed),
                env=training_env(code),
                cwd=code,
                check=True,
                stdout=handle,
                stderr=subprocess.STDOUT,
            )
        return sha256(last_pretrained(out) / WEIGHTS_FILE)
    finally:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(code)], check=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", help="the reference commit (any revision git accepts)")
    parser.add_argument("head", nargs="?", default="HEAD", help="the commit checked against it (default HEAD)")
    parser.add_argument("--steps", type=int, default=200, help="lerobot-train steps (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="lerobot-train --seed (default 0)")
    parser.add_argument(
        "--work",
        type=Path,
        default=None,
        help="keep the worktrees' training outputs and logs here (default: a temporary directory)",
    )
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="identical_training_") as tmp:
        work = (args.work or Path(tmp)).resolve()
        work.mkdir(parents=True, exist_ok=True)
        dataset = work / "dataset"
        make_synthetic_dataset(dataset, num_tasks=2, episodes_per_task=6, progress=False)
        digests = {
            name: train_commit(commit, name, work, dataset, args.steps, args.seed)
            for name, commit in (("base", args.base), ("head", args.head))
        }
    for (name, digest), commit in zip(digests.items(), (args.base, args.head), strict=True):
        print(f"{name} {commit}: {WEIGHTS_FILE} sha256 {digest}")
    identical = digests["base"] == digests["head"]
    print("identical" if identical else f"DIFFERENT: {WEIGHTS_FILE} after {args.steps} steps differs")
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
