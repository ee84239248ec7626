"""`predvla demo robot`: a tiny SO-101 recording and a PredVLA checkpoint trained on it, for the robot dry run.

Writes, under `--out` (default `outputs`, which git ignores):

- `so101_recordings/`: a LeRobot v3 dataset in an SO-101 follower's layout (six `*.pos` joints, cameras `front` and
  `wrist`, 30 fps), three short episodes of generated frames (tasks "pick up the red cube" and "put the cube in the
  box");
- `so101_frontend/` and `so101_predvla/`: its front end (`predvla fit-frontend`, random ResNet18 weights) and the
  dataset with the cached features (`predvla convert`);
- `predvla_so101/`: `--steps` steps of the real `lerobot-train` on it, with the default (Table 1-2) network.

The checkpoint has learnt nothing useful; it exercises the path a real one takes: saved processors, camera names,
task, the replay robot. About a minute on 2 cores. An existing `--out` folder of a finished run is left as it is.
"""

import argparse
import os
import subprocess
from pathlib import Path

from lerobot_predvla.cli import convert, fit_frontend
from lerobot_predvla.data.example_datasets import SO101, make_dataset
from lerobot_predvla.lerobot_commands import policy_args, train_command
from lerobot_predvla.utils.checkpoints import last_pretrained

EPISODES = [("pick up the red cube", 30), ("put the cube in the box", 30), ("pick up the red cube", 30)]
REPO_ID = "local/so101_recordings"


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("robot", help="a tiny SO-101 recording and a checkpoint for the dry run",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("outputs"), help="where to write (default: outputs)")
    parser.add_argument("--steps", type=int, default=2, help="lerobot-train steps (default 2)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    recordings, frontend, converted, train = (out / name for name in
                                              ("so101_recordings", "so101_frontend", "so101_predvla", "predvla_so101"))
    checkpoint = last_pretrained(train)
    if checkpoint.is_dir():
        print(f"predvla demo robot: {checkpoint} is there already; remove {train} to train it again.")
        return 0
    present = [str(p) for p in (recordings, frontend, converted, train) if p.exists()]
    if present:
        print(f"predvla demo robot: {', '.join(present)} exist(s) from an unfinished run; remove them and run "
              "again.")
        return 2
    make_dataset(recordings, SO101, EPISODES, repo_id=REPO_ID)
    parser = argparse.ArgumentParser(prog="predvla")
    subparsers = parser.add_subparsers()
    fit_frontend.add_parser(subparsers)
    convert.add_parser(subparsers)
    for argv in (["fit-frontend", "--dataset-root", str(recordings), "--vision-weights", "random", "--image-size", "64",
                  "--out", str(frontend)],
                 ["convert", "--dataset-root", str(recordings), "--frontend", str(frontend), "--out", str(converted),
                  "--repo-id", f"{REPO_ID}_predvla"]):
        parsed = parser.parse_args(argv)
        if parsed.func(parsed) != 0:
            return 1
    cmd = train_command(policy=policy_args("predvla", {"sequence_length": 32}), dataset_repo_id=f"{REPO_ID}_predvla",
                        dataset_root=converted, output_dir=train, steps=args.steps, batch_size=2,
                        save_freq=args.steps, device="cpu", extra=["--num_workers=0"])
    print("$", " ".join(cmd), flush=True)
    if subprocess.run(cmd, env={**os.environ, "HF_HUB_OFFLINE": "1"}).returncode != 0:
        return 1
    print(f"predvla demo robot: recording {recordings}, checkpoint {checkpoint}")
    return 0
