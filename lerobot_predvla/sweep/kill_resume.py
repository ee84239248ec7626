"""Fault-injection harness: SIGKILL a real `lerobot-train` at random moments and inside checkpoint writes, resume.

    python -m lerobot_predvla.sweep.kill_resume --output-dir OUT --kills 30 [--dataset-root DATA]

Each attempt runs `lerobot-train` in its own process group (`--resume=true` from `checkpoints/last` once there
is one) and ends it with SIGKILL to the whole group: either at a random moment (a random step after the resume
point is logged, then a random delay, which lands some kills inside checkpoint writes) or, every
`--forced-every`-th kill, exactly at a named point of a checkpoint write through the test hook
`PREDVLA_KILL_AT` (`utils/checkpoints.py`). After the planned kills the run is resumed to its last step. Then:

- the run reached `--steps`;
- every checkpoint `last` ever pointed to loads through LeRobot's `make_policy` with the training dataset
  (posteriors and the SHA-256 manifests of `pretrained_model/` and `training_state/` checked);
- its weights, optimizer state and posterior store belong to its step: `training_step.json` and every Adam
  step count equal the folder's step, and each episode's posterior step count equals the number of batches
  holding it in steps 1..step of LeRobot's data order (`EpisodeAwareSampler`, seed of the run);
- each resumed attempt started training at the step after `last` (nothing between the last complete
  checkpoint and the kill counted as done);
- against an uninterrupted run of the same seed (`--reference`): the max absolute difference of the weights,
  posterior store and optimizer state of every checkpoint, and of the logged losses.

Prints the report and writes it as JSON (`--report`).
"""

import argparse
import dataclasses
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from lerobot.utils.constants import CHECKPOINTS_DIR, LAST_CHECKPOINT_LINK, PRETRAINED_MODEL_DIR, TRAINING_STATE_DIR
from safetensors.torch import load_file

from lerobot_predvla import lerobot_commands
from lerobot_predvla.data.synthetic import make_synthetic_dataset
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE
from lerobot_predvla.utils.checkpoints import KILL_AT_ENV, KILL_POINTS
from lerobot_predvla.utils.io import atomic_write_json

_STEP_LINE = re.compile(r"step:(\d+) .* loss:([-+0-9.eE]+|nan)")
_RESUMED = re.compile(r"Resuming data order at epoch")
_POLL_S = 0.05
# The generated dataset used without --dataset-root (the test suite's: 8 episodes of 20-30 steps, 2 tasks).
SYNTHETIC = {"num_tasks": 2, "episodes_per_task": 4, "min_length": 20, "max_length": 30, "seed": 0}


@dataclass
class HarnessConfig:
    output_dir: Path
    dataset_root: Path | None = None  # None: a generated dataset beside output_dir (SYNTHETIC)
    repo_id: str = "local/predvla_synthetic"
    steps: int = 60
    save_freq: int = 3
    batch_size: int = 2
    sequence_length: int = 32
    seed: int = 3
    kills: int = 30
    forced_every: int = 3  # every n-th kill is forced at a named point of a checkpoint write (0: never)
    max_delay_s: float = 1.5  # random delay after the target step is logged
    min_kill_step: int = 1  # random kills come after this step (save_freq + 1: every kill is followed by a resume)
    rng_seed: int = 0
    reference: bool = True
    timeout_s: float = 3600.0  # per attempt: a guard against a hung lerobot-train
    extra_args: list[str] = field(default_factory=list)


@dataclass
class Kill:
    kind: str  # "random" or "forced:<point>@<step>"
    resumed_from: int  # step of `last` when the attempt started (0: fresh)
    reached: int  # last step the attempt logged as done
    last_after: int  # step of `last` after the kill
    seconds: float  # from launch to kill

    @property
    def steps_lost(self) -> int:
        return max(0, self.reached - self.last_after)


def train_command(cfg: HarnessConfig, out: Path, resume: bool) -> list[str]:
    """An attempt's whole `lerobot-train` command, with the resume flags from `checkpoints/last` when `resume`."""
    cmd = lerobot_commands.train_command(
        policy=lerobot_commands.policy_args("predvla", {"sequence_length": cfg.sequence_length}),
        dataset_repo_id=cfg.repo_id, dataset_root=cfg.dataset_root, output_dir=out, seed=cfg.seed, steps=cfg.steps,
        batch_size=cfg.batch_size, save_freq=cfg.save_freq, device="cpu",
        extra=["--num_workers=0", "--log_freq=1", *cfg.extra_args],
    )
    if resume:
        cmd += lerobot_commands.resume_args(out / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK / PRETRAINED_MODEL_DIR)
    return cmd


def last_step(out: Path) -> int:
    """The step `checkpoints/last` points at (0 when there is none)."""
    link = out / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK
    if not link.exists():
        return 0
    return int(json.loads((link / TRAINING_STATE_DIR / "training_step.json").read_text())["step"])


def logged_steps(log: Path) -> list[tuple[int, float]]:
    """(step, loss) of every step line of a `lerobot-train` log (run with --log_freq=1)."""
    return [(int(m.group(1)), float(m.group(2))) for m in _STEP_LINE.finditer(log.read_text(errors="replace"))]


class Attempt:
    """One `lerobot-train` process group, its output in `log`."""

    def __init__(self, cmd: list[str], log: Path, kill_at: str | None = None):
        env = {**os.environ, "HF_HUB_OFFLINE": "1"}
        env.pop(KILL_AT_ENV, None)
        if kill_at:
            env[KILL_AT_ENV] = kill_at
        self.log, self.started = log, time.monotonic()
        with open(log, "w") as f:
            self.proc = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, start_new_session=True)

    def reached(self) -> int:
        steps = logged_steps(self.log)
        return steps[-1][0] if steps else 0

    def kill(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)  # the whole group: no orphaned trainer
        except ProcessLookupError:
            pass
        self.proc.wait()

    def wait(self, timeout_s: float) -> int | None:
        """The exit code, or None when it ran past `timeout_s` (then it is killed)."""
        try:
            return self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            return None

    def kill_after_step(self, step: int, delay_s: float, timeout_s: float) -> bool:
        """SIGKILL `delay_s` after the log shows `step` done; False if the process ended first."""
        while self.reached() < step:
            if self.proc.poll() is not None:
                return False
            if time.monotonic() - self.started > timeout_s:
                break
            time.sleep(_POLL_S)
        time.sleep(delay_s)
        if self.proc.poll() is not None:
            return False
        self.kill()
        return True


def expected_posterior_steps(cfg: HarnessConfig, num_episodes: int) -> list[np.ndarray]:
    """Per step s (index s, 0..steps): how many of the batches 1..s held each episode, in LeRobot's data order."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.sampler import EpisodeAwareSampler

    meta = LeRobotDatasetMetadata(cfg.repo_id, root=cfg.dataset_root)
    starts, ends = meta.episodes["dataset_from_index"], meta.episodes["dataset_to_index"]
    sampler = EpisodeAwareSampler(starts, ends, shuffle=True, seed=cfg.seed)
    counts, out = np.zeros(num_episodes, dtype=np.int64), [np.zeros(num_episodes, dtype=np.int64)]
    while len(out) <= cfg.steps:
        frames = np.fromiter(iter(sampler), dtype=np.int64)  # one epoch; the DataLoader keeps its last batch
        episodes = np.searchsorted(np.asarray(ends), frames, side="right")
        for start in range(0, len(frames), cfg.batch_size):
            counts[np.unique(episodes[start : start + cfg.batch_size])] += 1
            out.append(counts.copy())
    return out[: cfg.steps + 1]


def checkpoint_dir(out: Path, step: int) -> Path:
    return out / CHECKPOINTS_DIR / f"{step:06d}"


def load_through_lerobot(cfg: HarnessConfig, ckpt: Path) -> None:
    """Build the policy from `ckpt` as `lerobot-train --resume` does: LeRobot's `make_policy` with the dataset."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy

    pretrained = ckpt / PRETRAINED_MODEL_DIR
    policy_cfg = PreTrainedConfig.from_pretrained(pretrained)
    policy_cfg.pretrained_path = pretrained
    make_policy(policy_cfg, ds_meta=LeRobotDatasetMetadata(cfg.repo_id, root=cfg.dataset_root))


def check_checkpoint(cfg: HarnessConfig, ckpt: Path, step: int, expected: list[np.ndarray]) -> list[str]:
    """What is wrong with the checkpoint of `step` (empty when it loads and all its parts belong to `step`)."""
    problems = []
    try:
        load_through_lerobot(cfg, ckpt)
    except Exception as err:  # noqa: BLE001  (reported, not raised: the harness counts failures)
        return [f"{ckpt}: does not load: {err}"]
    recorded = json.loads((ckpt / TRAINING_STATE_DIR / "training_step.json").read_text())["step"]
    if recorded != step:
        problems.append(f"{ckpt}: training_step.json says {recorded}")
    optimizer = load_file(ckpt / TRAINING_STATE_DIR / "optimizer_state.safetensors")
    adam_steps = {float(v) for k, v in optimizer.items() if k.endswith("/step")}
    if adam_steps != {float(step)}:
        problems.append(f"{ckpt}: optimizer step counts {sorted(adam_steps)}")
    posterior_steps = load_file(ckpt / PRETRAINED_MODEL_DIR / POSTERIOR_STORE_FILE)["steps"].numpy()
    if not np.array_equal(posterior_steps, expected[step]):
        problems.append(f"{ckpt}: posterior step counts {posterior_steps.tolist()}, data order gives "
                        f"{expected[step].tolist()}")
    return problems


def max_abs_difference(a: Path, b: Path) -> float:
    x, y = load_file(a), load_file(b)
    if x.keys() != y.keys():
        return float("inf")
    return max((float((x[k].double() - y[k].double()).abs().max()) if x[k].numel() else 0.0) for k in x)


def compare_with_reference(run: Path, reference: Path, steps: list[int]) -> dict[str, float]:
    worst = {"weights": 0.0, "posterior_store": 0.0, "optimizer_state": 0.0}
    files = {"weights": f"{PRETRAINED_MODEL_DIR}/model.safetensors",
             "posterior_store": f"{PRETRAINED_MODEL_DIR}/{POSTERIOR_STORE_FILE}",
             "optimizer_state": f"{TRAINING_STATE_DIR}/optimizer_state.safetensors"}
    for step in steps:
        for key, rel in files.items():
            diff = max_abs_difference(checkpoint_dir(run, step) / rel, checkpoint_dir(reference, step) / rel)
            worst[key] = max(worst[key], diff)
    return worst


def run_harness(cfg: HarnessConfig) -> dict:
    out, rng = Path(cfg.output_dir), random.Random(cfg.rng_seed)
    if cfg.dataset_root is None:
        cfg = dataclasses.replace(cfg, dataset_root=out.with_name(out.name + "_data"))
        if not cfg.dataset_root.exists():
            make_synthetic_dataset(cfg.dataset_root, cfg.repo_id, progress=False, **SYNTHETIC)
    logs = out.with_name(out.name + "_logs")
    for path in (out, logs):
        if path.exists():
            shutil.rmtree(path)
    logs.mkdir(parents=True)
    kills: list[Kill] = []
    pointed, problems, restarts, attempts, resumes = set(), [], 0, 0, 0
    losses: dict[int, float] = {}  # step -> loss of the attempt whose checkpoints were kept
    started = time.monotonic()
    while True:
        resumed_from = last_step(out)
        if resumed_from == 0 and out.exists():  # killed before its first checkpoint was linked: start afresh
            shutil.rmtree(out)
            restarts += 1
        if resumed_from >= cfg.steps:
            break
        attempts += 1
        resumes += resumed_from > 0
        log = logs / f"attempt_{attempts:03d}.log"
        planned = len(kills) < cfg.kills
        forced = planned and cfg.forced_every > 0 and (len(kills) + 1) % cfg.forced_every == 0
        kill_at = None
        if forced:
            point = KILL_POINTS[(len(kills) // cfg.forced_every) % len(KILL_POINTS)]
            target = min(cfg.steps, (resumed_from // cfg.save_freq + 1) * cfg.save_freq)
            kill_at = f"{point}@{target}"
        attempt = Attempt(train_command(cfg, out, resume=resumed_from > 0), log, kill_at)
        if planned and not forced:
            first = max(resumed_from + 1, cfg.min_kill_step)
            target = rng.randint(first, min(cfg.steps, max(first, resumed_from + 2 * cfg.save_freq)))
            killed = attempt.kill_after_step(target, rng.uniform(0.0, cfg.max_delay_s), cfg.timeout_s)
            rc = attempt.proc.returncode if not killed else -signal.SIGKILL
        else:
            rc = attempt.wait(cfg.timeout_s)
            killed = rc == -signal.SIGKILL
        done = logged_steps(log)
        if resumed_from > 0 and done and done[0][0] != resumed_from + 1:
            problems.append(f"{log}: resumed from `last` at step {resumed_from} but trained step {done[0][0]} first")
        if resumed_from > 0 and done and not _RESUMED.search(log.read_text(errors="replace")):
            problems.append(f"{log}: no 'Resuming data order' line")
        for step, loss in done:
            losses[step] = loss
        if (target_link := out / CHECKPOINTS_DIR / LAST_CHECKPOINT_LINK).is_symlink():
            pointed.add(int(os.readlink(target_link)))
        if killed and planned:
            kills.append(Kill(f"forced:{kill_at}" if forced else "random", resumed_from, attempt.reached(),
                              last_step(out), time.monotonic() - attempt.started))
        elif rc != 0:
            ended = f"ran past {cfg.timeout_s:.0f} s" if rc is None else f"exited with {rc}"
            problems.append(f"{log}: lerobot-train {ended}: {log.read_text(errors='replace')[-800:]}")
            break
    reached = last_step(out)
    if reached != cfg.steps:
        problems.append(f"the run ended at step {reached}, not {cfg.steps}")
    for kill in kills:
        if kill.last_after < kill.resumed_from:
            problems.append(f"a kill moved `last` back from {kill.resumed_from} to {kill.last_after}")
    # Every save step that `last` pointed to (the intermediate ones of one attempt are seen as links at its end).
    saved = sorted(s for s in pointed | {s for s in range(cfg.save_freq, reached + 1, cfg.save_freq)}
                   if checkpoint_dir(out, s).is_dir())
    num_episodes = int(load_file(checkpoint_dir(out, reached) / PRETRAINED_MODEL_DIR / POSTERIOR_STORE_FILE)
                       ["steps"].numel()) if reached else 0
    expected = expected_posterior_steps(cfg, num_episodes) if reached else []
    for step in saved:
        problems += check_checkpoint(cfg, checkpoint_dir(out, step), step, expected)
    report = {
        "config": {k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(cfg).items()},
        "attempts": attempts,
        "kills": len(kills),
        "forced_kills": sum(k.kind != "random" for k in kills),
        "resumes": resumes,
        "restarts_before_first_checkpoint": restarts,
        "checkpoints_checked": len(saved),
        "failures": len(problems),
        "problems": problems,
        "steps_lost_per_kill": {"max": max((k.steps_lost for k in kills), default=0),
                                "mean": float(np.mean([k.steps_lost for k in kills])) if kills else 0.0},
        "kill_log": [{**dataclasses.asdict(k), "steps_lost": k.steps_lost} for k in kills],
        "wall_s": round(time.monotonic() - started, 1),
    }
    if cfg.reference and reached == cfg.steps:
        reference = out.with_name(out.name + "_reference")
        if reference.exists():
            shutil.rmtree(reference)
        ref_log = logs / "reference.log"
        rc = Attempt(train_command(cfg, reference, resume=False), ref_log).wait(cfg.timeout_s)
        if rc != 0:
            problems.append(f"{ref_log}: the uninterrupted run exited with {rc} (None: ran past --timeout-s)")
        else:
            ref_losses = dict(logged_steps(ref_log))
            report["reference"] = {
                "max_abs_difference": compare_with_reference(out, reference, saved),
                "final_loss": {"resumed": losses.get(cfg.steps), "uninterrupted": ref_losses.get(cfg.steps)},
                "max_abs_loss_difference": max(abs(losses[s] - ref_losses[s]) for s in losses if s in ref_losses),
            }
        report["failures"] = len(problems)
    return report


def parse_args(argv: list[str] | None = None) -> tuple[HarnessConfig, Path | None]:
    """The harness config and the report path; unknown arguments go to every `lerobot-train` call."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset-root", type=Path,
                        help="a LeRobot dataset PredVLA can train on (default: generate SYNTHETIC beside the run)")
    parser.add_argument("--output-dir", type=Path, required=True, help="the run's folder (replaced); logs beside it")
    for name in ("repo_id", "steps", "save_freq", "batch_size", "sequence_length", "seed", "kills", "forced_every",
                 "max_delay_s", "min_kill_step", "rng_seed", "timeout_s"):
        default = getattr(HarnessConfig, name)
        parser.add_argument(f"--{name.replace('_', '-')}", type=type(default), default=default)
    parser.add_argument("--no-reference", dest="reference", action="store_false",
                        help="skip the uninterrupted run of the same seed")
    parser.add_argument("--report", type=Path, help="write the report as JSON here")
    args, extra = parser.parse_known_args(argv)
    report = vars(args).pop("report")
    return HarnessConfig(**vars(args), extra_args=extra), report


def main(argv: list[str] | None = None) -> int:
    cfg, report_path = parse_args(argv)
    if cfg.steps < cfg.save_freq or cfg.kills < 0:
        raise SystemExit("--steps must be at least --save-freq and --kills non-negative")
    report = run_harness(cfg)
    text = json.dumps({k: v for k, v in report.items() if k != "kill_log"}, indent=2)
    print(text)
    if report_path is not None:
        atomic_write_json(report_path, report)
    return 1 if report["failures"] else 0


if __name__ == "__main__":
    torch.set_num_threads(1)
    sys.exit(main())
