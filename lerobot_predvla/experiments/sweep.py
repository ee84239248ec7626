"""Experiment runner: `lerobot-train` then `lerobot-eval` for configurations x suites x seeds.

A sweep file (YAML or JSON) lists configurations; every (configuration, suite, seed) is one run whose result is
a JSON record `RUNS_DIR/records/<config>/<suite>/seed<k>.json`. Runs with a record are skipped, a training
killed midway resumes from its last checkpoint (`lerobot-train --resume=true`), an evaluation killed midway is
redone. Inference-time variants (`checkpoint_from: <config>`) evaluate another configuration's checkpoints
with extra `lerobot-eval` arguments and train nothing themselves.

A configuration with `lr_sweep` first chooses its learning rate on held-out demonstrations (`lr_selection.py`):
one shorter candidate training per rate, then its own training at the chosen rate.

Scaling out: `--shard i/n` runs every n-th training unit (a checkpoint with all evaluations that use it), so n
processes or hosts sharing RUNS_DIR split a sweep without overlap; `accelerate_processes > 1` trains each run
with `accelerate launch --multi_gpu` (LeRobot's multi-GPU path).
"""

import filecmp
import json
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

from lerobot_predvla.columns import SUITES
from lerobot_predvla.experiments.eval_info import EVAL_INFO_FILE, EvalInfoError, parse_eval_info
from lerobot_predvla.experiments.logs import compact_log
from lerobot_predvla.experiments.lr_selection import (
    CRITERION,
    PENDING_LR,
    LRSweep,
    candidate_name,
    candidate_path,
    choose,
    divergence,
    heldout_episodes,
    heldout_losses,
    selection_path,
)
from lerobot_predvla.policies.recipe import NOT_RECIPE
from lerobot_predvla.sims.libero.expert.motion import DEFAULT_HALF_TURN, HALF_TURN_RULES
from lerobot_predvla.sims.libero.protocol import EVAL_ENV_TYPE, PAPER_EPISODE_LENGTH, PAPER_EPISODES_PER_TASK
from lerobot_predvla.utils.checkpoints import last_pretrained, prune_checkpoints
from lerobot_predvla.utils.io import atomic_write_json
from lerobot_predvla.utils.manifest import sha256_file
from lerobot_predvla.utils.parameters import count_parameters
from lerobot_predvla.utils.versions import machine, package_versions

PAPER_TRAIN_STEPS = 30_000
PAPER_BATCH_SIZE = 32
GROUPS = ("main", "baseline", "ladder", "ablation", "corruption")
# The unrelated episode of a corruption run comes from another suite's dataset, so it is unrelated to every task
# of the evaluated suite (Section 4.4: "observations from an unrelated episode").
CORRUPTION_SOURCE = {"libero_spatial": "libero_goal", "libero_goal": "libero_object",
                     "libero_object": "libero_spatial", "libero_10": "libero_spatial"}
CORRUPTION_KEYS = {"channel", "alpha", "source_suite", "episode", "open_loop"}
TRAIN_DONE_FILE = "predvla_sweep_train.json"  # written beside a finished training's checkpoints
EVAL_WALL_FILE = "predvla_sweep_eval.json"  # wall time of one evaluation part, beside its eval_info.json

Executor = Callable[[list[str], Path], int]  # (command, log file) -> exit code


MAPPING_FIELDS = ("normalization_mapping",)  # config fields of type dict, set whole on the command line


class SweepError(ValueError):
    """A malformed sweep file or an impossible request."""


def eval_run_dir(runs_dir: Path, config: str, suite: str, seed: int) -> Path:
    """Where a run's evaluation writes: its eval_info.json, or one task part per subfolder."""
    return Path(runs_dir) / "eval" / config / suite / f"seed{seed}"


def run_log_path(runs_dir: Path, name: str, suite: str, seed: int, stage: str) -> Path:
    """Where a stage (train, eval, publish, or a data stage under name "data") of a run writes its log."""
    return Path(runs_dir) / "logs" / name / suite / f"seed{seed}.{stage}.log"


def _recipe(fields: dict) -> dict:
    """The policy fields of `fields` that change what is computed (NOT_RECIPE left out)."""
    return {k: v for k, v in fields.items() if k not in NOT_RECIPE}


def _as_args(values: dict, prefix: str) -> list[str]:
    """{"tau": [30, 14, 8, 2], "x": {"y": 1}} -> ["--policy.tau=[30,14,8,2]", "--policy.x.y=1"]; a dict-typed field
    (MAPPING_FIELDS, e.g. `normalization_mapping`) is passed whole as JSON, the only form draccus parses for it."""
    args = []
    for key, value in values.items():
        if key in MAPPING_FIELDS:
            args.append(f"--{prefix}.{key}={json.dumps(value)}")
        elif isinstance(value, dict):
            args += _as_args(value, f"{prefix}.{key}")
        elif isinstance(value, bool):
            args.append(f"--{prefix}.{key}={str(value).lower()}")
        elif isinstance(value, list | tuple):
            args.append(f"--{prefix}.{key}=[{','.join(map(str, value))}]")
        elif value is not None:
            args.append(f"--{prefix}.{key}={value}")
    return args


@dataclass
class ConfigSpec:
    """One configuration of a sweep file.

    Args:
        name: Unique name (a run directory component and the report's row label), e.g. `predvla`, `L3`, `A6`.
        group: Report section: main, baseline, ladder, ablation or corruption.
        label: Description shown in the report (e.g. "- Online ER (n_itr=0)").
        policy: A policy type (`predvla`) or a JSON file of policy fields with `type` (`configs/policy/L3.json`),
            turned into `--policy.type=... --policy.<field>=...`.
        policy_overrides: Extra policy fields for training (`{"tau": [8, 8, 8, 8]}`).
        train_args: Extra raw `lerobot-train` arguments.
        suite_overrides: Policy fields per suite (`{"libero_10": {"tau": [30, 14, 8, 2], "sequence_length": 500}}`).
        eval_overrides: Policy fields at evaluation (`{"er_iterations": 0}`).
        eval_args: Extra raw `lerobot-eval` arguments.
        checkpoint_from: Evaluate this configuration's checkpoints instead of training (inference-time variants).
        compare_to: Ablations: the intact configuration for paired differences; ladder: the preceding rung;
            baselines: the model whose episodes theirs are paired with.
        branch: Ladder side branch (dashed in the figure, not part of the main chain).
        corruption: A corruption-curve point (Section 4.4): `{"channel": "vision" | "proprio", "alpha": 0.25}`, optional
            `source_suite` (whose dataset holds the unrelated episode; default: another suite, see
            `CORRUPTION_SOURCE`), `episode` (its episode index, default 0) and `open_loop` (the configuration whose
            success the report draws as the open-loop line). Becomes `--policy.er_corruption_*` at evaluation.
        init_states: Evaluate from the benchmark's official init states (True, the default and the paper's protocol)
            or from fresh randomised resets (False: `--env.init_states=false`, object placements sampled by the
            simulator from `eval_seed`).
        eval_seed: `lerobot-eval --seed` (default: the run's training seed). With `init_states: false` it picks the
            resets, so a checkpoint can be evaluated on resets no training or earlier evaluation saw.
        suites, seeds, steps, n_episodes: Per-configuration replacements of the sweep-wide values. `--seeds` keeps
            a configuration's own seeds only where they overlap its list (`seeds: [1, 2]` with `--seeds 0` runs
            nothing), and `--suites` its own suites likewise.
        lr_sweep: Choose `optimizer_lr` before training (`LRSweep`'s fields: `{rates: [1e-4, 3e-4, 1e-3, 3e-3],
            steps: 10000, eval_split: 0.1}`): one candidate per rate, the one with the lowest held-out loss wins.
        paper: The paper's published success (%) of the same configuration per suite, `{libero_object: [89.24, 6.13]}`
            (mean and standard deviation over its seeds, or the mean alone); `predvla report` sets it beside ours.
        pool_with: The configuration this one extends with further training seeds (the same model and evaluation,
            e.g. at fewer episodes per task: the same trained configuration, `init_states` and `eval_overrides` but
            for fields of where or how fast they compute): `predvla report` adds a row over the union of their seeds
            and pools their paired episodes. With `compare_to` on both, this one's must pool with the other's (open
            loop on seeds 1-2 against error regression on seeds 1-2 pools with open loop on seed 0 against error
            regression on seed 0).
    """

    name: str
    group: str = "main"
    label: str = ""
    policy: str = "predvla"
    policy_overrides: dict = field(default_factory=dict)
    train_args: list[str] = field(default_factory=list)
    suite_overrides: dict[str, dict] = field(default_factory=dict)
    eval_overrides: dict = field(default_factory=dict)
    eval_args: list[str] = field(default_factory=list)
    checkpoint_from: str | None = None
    compare_to: str | None = None
    branch: bool = False
    corruption: dict | None = None
    init_states: bool = True
    eval_seed: int | None = None
    suites: list[str] | None = None
    seeds: list[int] | None = None
    steps: int | None = None
    n_episodes: int | None = None
    lr_sweep: LRSweep | None = None
    paper: dict[str, float | list[float]] = field(default_factory=dict)
    pool_with: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.lr_sweep, dict):  # as read from a sweep file
            self.lr_sweep = LRSweep(**self.lr_sweep)

    def policy_args(self, base_dir: Path, suite: str) -> list[str]:
        if self.policy.endswith(".json"):
            path = Path(self.policy) if Path(self.policy).is_absolute() else base_dir / self.policy
            if not path.is_file():
                raise SweepError(f"configuration {self.name}: policy file {path} not found.")
            fields = json.loads(path.read_text())
            fields = dict(fields.get("policy", fields))  # a `lerobot-train --config_path` file nests the policy
            if "type" not in fields:
                raise SweepError(f"{path}: expected a `type` field naming the policy type.")
            policy_type = fields.pop("type")
        else:
            policy_type, fields = self.policy, {}
        fields = {**fields, **self.policy_overrides, **self.suite_overrides.get(suite, {})}
        return [f"--policy.type={policy_type}", *_as_args(fields, "policy")]


@dataclass
class Settings:
    """Sweep-wide values; the paper's protocol unless the sweep file or the command line says otherwise."""

    seeds: list[int] = field(default_factory=lambda: [0])
    suites: list[str] = field(default_factory=lambda: list(SUITES))
    # suite -> {repo_id, root, train_root}. train_root (optional): training reads this copy of `root` without camera
    # frames (`predvla features-only`, made when missing): the same samples and updates, no video decoding.
    datasets: dict[str, dict] = field(default_factory=dict)
    steps: int = PAPER_TRAIN_STEPS
    batch_size: int = PAPER_BATCH_SIZE
    save_freq: int = 5_000
    keep_every: int | None = None  # after a training, keep only every keep_every-th step's checkpoint and the last
    # After a training, its final model as `predvla push --out` writes it (no posteriors, no optimizer state: a few
    # MB, to commit) in this folder, a template of {config}, {suite} and {seed} relative to the sweep file; the
    # training record and every evaluation then read that copy, so a fresh clone evaluates without the runs dir.
    publish: str | None = None
    train_device: str = "cuda"
    train_args: list[str] = field(default_factory=list)
    accelerate_processes: int = 1
    n_episodes: int = PAPER_EPISODES_PER_TASK
    episode_length: int = PAPER_EPISODE_LENGTH
    eval_batch_size: int = 1
    eval_device: str = "cuda"
    env_type: str = EVAL_ENV_TYPE
    eval_args: list[str] = field(default_factory=list)
    eval_tasks: list[int] | None = None  # evaluate task by task: one lerobot-eval (and one resumable unit) per task
    eval_workers: int = 1  # task parts evaluated at once, one lerobot-eval process each (one per CPU core)
    data: dict[str, "DataSpec"] = field(default_factory=dict)  # suite -> how its dataset is made


@dataclass
class DataSpec:
    """How `predvla sweep` makes a suite's dataset before training: expert demonstrations (`predvla demos`), the
    front end (`predvla fit-frontend`) and the conversion (`predvla convert`) into the suite's `datasets` root.
    Each stage is skipped when its output exists (demonstrations task by task), so a killed run resumes.

    Args:
        hdf5: Root of the demonstrations (`<hdf5>/<suite>/*_demo.hdf5`).
        frontend: Directory of the fitted front-end artefact.
        per_task: Successful expert demonstrations per task (the paper's datasets have 50).
        tasks: Task ids (default: every task of the suite).
        render_interval: Render the cameras every k-th step (4 = PredVLA's visual refresh).
        demo_seed: Seed of the randomised resets of the demonstrations.
        init_noise: Std (rad) of the noise on the arm's initial joint angles of the demonstrations
            (`predvla demos --init-noise`; 0: LIBERO ControlEnv's fixed start, 0.02: the official init states').
        half_turn: Which of a finger direction and its half turn the expert grasps with (`predvla demos
            --half-turn`): 'nearest' (the current fingers') or 'wrist_centre' (the wrist joint nearer the middle of
            its range: one wrist branch per task also with init_noise).
        hold_steps: Idle steps (arm still, gripper open) recorded after each demonstration's success (`predvla demos
            --hold-steps`; 0: episodes end at success, as LIBERO's).
        vision_weights: ResNet18 weights of the front end ('imagenet', a .pth file, or 'random': the offline
            substitute, printed as such).
        language_from: Instructions of the language PCA: 'libero' (all 40 of the task list, Section 4.1) or 'demos'.
        frame_stride: Fit the visual PCA on every n-th frame.
        workers: `predvla demos` processes run at once (one per CPU core), each on every `workers`-th missing task
            (logs `seed0.demos.tasks<k>.log`). The demonstrations are the same for any value: an episode's seed
            depends only on `demo_seed`, its task and its attempt.
    """

    hdf5: str
    frontend: str
    per_task: int = 50
    tasks: list[int] | None = None
    render_interval: int = 4
    demo_seed: int = 0
    init_noise: float = 0.0
    half_turn: str = DEFAULT_HALF_TURN
    hold_steps: int = 0
    vision_weights: str = "imagenet"
    language_from: str = "libero"
    frame_stride: int = 4
    workers: int = 1


@dataclass(frozen=True)
class Run:
    config: str
    suite: str
    seed: int

    @property
    def key(self) -> str:
        return f"{self.config}/{self.suite}/seed{self.seed}"


@dataclass
class Sweep:
    settings: Settings
    configs: dict[str, ConfigSpec]
    base_dir: Path  # relative paths in the sweep file are relative to it

    @classmethod
    def load(cls, path: Path) -> "Sweep":
        path = Path(path)
        if not path.is_file():
            raise SweepError(f"{path}: sweep file not found.")
        text = path.read_text()
        if path.suffix == ".json":
            raw = json.loads(text)
        else:
            import yaml

            raw = yaml.safe_load(text)
        if not isinstance(raw, dict) or not raw.get("configs"):
            raise SweepError(f"{path}: expected a mapping with a non-empty `configs` list.")
        unknown = set(raw) - {"seeds", "suites", "datasets", "data", "train", "eval", "configs"}
        if unknown:
            raise SweepError(f"{path}: unknown top-level keys {sorted(unknown)}.")
        train, evaluation = raw.get("train", {}), raw.get("eval", {})
        try:
            settings = Settings(
                seeds=list(raw.get("seeds", [0])),
                suites=list(raw.get("suites", SUITES)),
                datasets=dict(raw.get("datasets", {})),
                steps=int(train.get("steps", PAPER_TRAIN_STEPS)),
                batch_size=int(train.get("batch_size", PAPER_BATCH_SIZE)),
                save_freq=int(train.get("save_freq", 5_000)),
                keep_every=int(train["keep_every"]) if train.get("keep_every") is not None else None,
                publish=str(train["publish"]) if train.get("publish") is not None else None,
                train_device=str(train.get("device", "cuda")),
                train_args=list(train.get("args", [])),
                accelerate_processes=int(train.get("accelerate_processes", 1)),
                n_episodes=int(evaluation.get("n_episodes", PAPER_EPISODES_PER_TASK)),
                episode_length=int(evaluation.get("episode_length", PAPER_EPISODE_LENGTH)),
                eval_batch_size=int(evaluation.get("batch_size", 1)),
                eval_device=str(evaluation.get("device", "cuda")),
                env_type=str(evaluation.get("env_type", EVAL_ENV_TYPE)),
                eval_args=list(evaluation.get("args", [])),
                eval_tasks=[int(t) for t in evaluation["tasks"]] if "tasks" in evaluation else None,
                eval_workers=int(evaluation.get("workers", 1)),
                data={suite: DataSpec(**spec) for suite, spec in raw.get("data", {}).items()},
            )
            configs = [ConfigSpec(**entry) for entry in raw["configs"]]
        except TypeError as err:
            raise SweepError(f"{path}: {err}") from err
        if settings.eval_workers < 1:
            raise SweepError(f"{path}: eval.workers must be >= 1, got {settings.eval_workers}.")
        if settings.keep_every is not None and (settings.keep_every < 1 or settings.keep_every % settings.save_freq):
            raise SweepError(f"{path}: train.keep_every must be a positive multiple of train.save_freq "
                             f"({settings.save_freq}), got {settings.keep_every}.")
        if settings.publish is not None:
            try:
                settings.publish.format(config="c", suite="s", seed=0)
            except (KeyError, IndexError, ValueError) as err:
                raise SweepError(f"{path}: train.publish {settings.publish!r}: expected a folder with only {{config}}, "
                                 f"{{suite}} and {{seed}} to fill in ({err!r}).") from err
        for suite, spec in settings.data.items():
            if spec.half_turn not in HALF_TURN_RULES:
                raise SweepError(f"{path}: data.{suite}.half_turn must be one of {HALF_TURN_RULES}, "
                                 f"got {spec.half_turn!r}.")
            if spec.hold_steps < 0:
                raise SweepError(f"{path}: data.{suite}.hold_steps must be >= 0, got {spec.hold_steps}.")
            if spec.workers < 1:
                raise SweepError(f"{path}: data.{suite}.workers must be >= 1, got {spec.workers}.")
        sweep = cls(settings, {}, path.parent)
        for spec in configs:
            if spec.name in sweep.configs:
                raise SweepError(f"{path}: configuration name {spec.name!r} appears twice.")
            for name, own in (("suites", spec.suites), ("seeds", spec.seeds)):
                # In the file only: `--seeds` / `--suites` may leave a configuration none of its own (not run).
                if own is not None and not own:
                    raise SweepError(f"{path}: configuration {spec.name}: `{name}` is empty; leave it out to use the "
                                     f"sweep's {name}.")
            sweep.configs[spec.name] = spec
        sweep.validate(path)
        return sweep

    def validate(self, where: Path) -> None:
        for spec in self.configs.values():
            if spec.group not in GROUPS:
                raise SweepError(f"{where}: configuration {spec.name}: group {spec.group!r} is not one of {GROUPS}.")
            for ref in (spec.checkpoint_from, spec.compare_to, spec.pool_with):
                if ref is not None and ref not in self.configs:
                    raise SweepError(f"{where}: configuration {spec.name} refers to unknown configuration {ref!r}.")
            if spec.checkpoint_from and (spec.train_args or spec.policy_overrides or spec.suite_overrides):
                raise SweepError(
                    f"{where}: configuration {spec.name} evaluates {spec.checkpoint_from}'s checkpoints; "
                    "give it eval_overrides/eval_args only."
                )
            if spec.checkpoint_from and self.configs[spec.checkpoint_from].checkpoint_from:
                raise SweepError(f"{where}: configuration {spec.name}: checkpoint_from must name a trained config.")
            if spec.pool_with is not None:
                self.validate_pool(spec, where)
            if spec.corruption is not None:
                self.validate_corruption(spec, where)
            if spec.lr_sweep is not None:
                self.validate_lr_sweep(spec, where)
            for suite, value in spec.paper.items():
                numbers = value if isinstance(value, list) else [value]
                if suite not in SUITES or not 1 <= len(numbers) <= 2 or not all(
                        isinstance(x, int | float) for x in numbers):
                    raise SweepError(f"{where}: configuration {spec.name}: `paper` maps a suite of {SUITES} to a "
                                     f"success (%) or [mean, std]; got {suite}: {value!r}.")
            unknown = set(self.suites_of(spec)) - set(SUITES)
            if unknown:
                raise SweepError(f"{where}: configuration {spec.name}: unknown suites {sorted(unknown)}; use {SUITES}.")
            missing = [s for s in self.suites_of(spec) if s not in self.settings.datasets]
            if missing:
                raise SweepError(f"{where}: `datasets` has no entry (repo_id, root) for suites {missing}.")
        for suite in self.settings.data:
            if not self.settings.datasets.get(suite, {}).get("root"):
                raise SweepError(f"{where}: `data` makes {suite}'s dataset, so `datasets.{suite}` needs a `root`.")
        for suite, entry in self.settings.datasets.items():
            if entry.get("train_root") and not entry.get("root"):
                raise SweepError(f"{where}: `datasets.{suite}.train_root` is copied from a local dataset: give "
                                 "its `root` too.")

    def validate_pool(self, spec: ConfigSpec, where: Path) -> None:
        target = self.configs[spec.pool_with]
        problem = None
        if target.name == spec.name or target.pool_with is not None:
            problem = "must name a configuration that pools with none (the row that gathers the seeds)"
        elif ((spec.checkpoint_from or spec.name) != (target.checkpoint_from or target.name)
              or _recipe(spec.eval_overrides) != _recipe(target.eval_overrides)
              or spec.init_states != target.init_states):
            problem = (f"it must evaluate the model {target.name} evaluates, as it does (checkpoint_from, "
                       "eval_overrides but for where or how fast they compute, init_states)")
        elif spec.compare_to and target.compare_to and self.configs[spec.compare_to].pool_with != target.compare_to:
            # One of them without compare_to is fine: the pool's paired episodes are then the other's alone.
            problem = (f"its compare_to {spec.compare_to!r} must pool with {target.compare_to!r}, what "
                       f"{target.name} compares to, so that the paired episodes pool")
        if problem:
            raise SweepError(f"{where}: configuration {spec.name}: pool_with {spec.pool_with!r}: {problem}.")

    def validate_lr_sweep(self, spec: ConfigSpec, where: Path) -> None:
        problems = spec.lr_sweep.problems()
        if spec.checkpoint_from:
            problems.append("a configuration that trains nothing has no learning rate to choose (checkpoint_from)")
        overridden = ["policy_overrides"] if "optimizer_lr" in spec.policy_overrides else []
        overridden += [f"suite_overrides.{s}" for s, o in spec.suite_overrides.items() if "optimizer_lr" in o]
        if overridden:
            problems.append(f"optimizer_lr is chosen by the sweep; remove it from {', '.join(overridden)}")
        taken = [name for name in (candidate_name(spec.name, r) for r in spec.lr_sweep.rates) if name in self.configs]
        if taken:
            problems.append(f"the candidate run names {taken} are configuration names")
        if problems:
            raise SweepError(f"{where}: configuration {spec.name}: lr_sweep: {'; '.join(problems)}.")

    def validate_corruption(self, spec: ConfigSpec, where: Path) -> None:
        c = spec.corruption
        if not isinstance(c, dict) or c.get("channel") not in ("vision", "proprio") or "alpha" not in c:
            raise SweepError(f"{where}: configuration {spec.name}: corruption needs channel (vision or proprio) and "
                             f"alpha, got {c!r}.")
        unknown = sorted(set(c) - CORRUPTION_KEYS)
        if unknown:
            raise SweepError(f"{where}: configuration {spec.name}: unknown corruption keys {unknown}; expected "
                             f"{sorted(CORRUPTION_KEYS)}.")
        if not 0.0 <= float(c["alpha"]) <= 1.0:
            raise SweepError(f"{where}: configuration {spec.name}: corruption alpha {c['alpha']} is not in [0, 1].")
        sources = {self.corruption_source(spec, suite) for suite in self.suites_of(spec)}
        missing = sorted(sources - set(self.settings.datasets))
        if missing:
            raise SweepError(f"{where}: configuration {spec.name}: the corruption source suites {missing} have no "
                             "entry in `datasets`.")
        remote = sorted(s for s in sources if not self.settings.datasets[s].get("root"))
        if remote:
            raise SweepError(f"{where}: configuration {spec.name}: the corruption source datasets of {remote} need "
                             "a local `root`.")

    @staticmethod
    def corruption_source(spec: ConfigSpec, suite: str) -> str:
        return spec.corruption.get("source_suite") or CORRUPTION_SOURCE[suite]

    def suites_of(self, spec: ConfigSpec) -> list[str]:
        return self.settings.suites if spec.suites is None else spec.suites

    def seeds_of(self, spec: ConfigSpec) -> list[int]:
        return self.settings.seeds if spec.seeds is None else spec.seeds

    def trained_config(self, spec: ConfigSpec) -> ConfigSpec:
        return self.configs[spec.checkpoint_from] if spec.checkpoint_from else spec

    def steps_of(self, spec: ConfigSpec) -> int:
        return self.trained_config(spec).steps or self.settings.steps

    def runs(self, configs: list[str] | None = None) -> list[Run]:
        names = configs or list(self.configs)
        unknown = [n for n in names if n not in self.configs]
        if unknown:
            raise SweepError(f"--configs: unknown configurations {unknown}; the sweep file has {list(self.configs)}.")
        return [
            Run(name, suite, seed)
            for name in names
            for suite in self.suites_of(self.configs[name])
            for seed in self.seeds_of(self.configs[name])
        ]

    def units(self, runs: list[Run]) -> list[tuple[tuple[str, str, int], list[Run]]]:
        """Runs grouped by the checkpoint they need ((trained config, suite, seed)), in a stable order."""
        grouped: dict[tuple[str, str, int], list[Run]] = {}
        for run in runs:
            trained = self.trained_config(self.configs[run.config]).name
            grouped.setdefault((trained, run.suite, run.seed), []).append(run)
        order = {name: i for i, name in enumerate(self.configs)}
        return sorted(grouped.items(), key=lambda item: (order[item[0][0]], SUITES.index(item[0][1]), item[0][2]))


def parse_shard(text: str) -> tuple[int, int]:
    """"i/n" with 0 <= i < n."""
    try:
        index, count = (int(x) for x in text.split("/"))
    except ValueError as err:
        raise SweepError(f"--shard {text!r}: expected i/n, e.g. 0/4.") from err
    if count < 1 or not 0 <= index < count:
        raise SweepError(f"--shard {text!r}: need 0 <= i < n.")
    return index, count


def subprocess_executor(command: list[str], log: Path) -> int:
    """Run a command with stdout and stderr appended to `log`, then keep only its progress bars' last states."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a") as out:
        out.write(f"$ {' '.join(command)}\n")
        out.flush()
        code = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, check=False).returncode
    compact_log(log)
    return code


def versions() -> dict[str, str]:
    """Package versions, the plugin's git commit when it runs from a checkout, and the machine."""
    found = {**package_versions(), "machine": machine()}
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent, check=False).stdout.strip()
        found["lerobot_predvla_git"] = commit or "unknown"
    except OSError:
        found["lerobot_predvla_git"] = "unknown"
    return found


@dataclass
class Runner:
    """Executes the runs of a sweep under `runs_dir`; `execute` is injectable (tests use a fake)."""

    sweep: Sweep
    runs_dir: Path
    execute: Executor = subprocess_executor
    lerobot_train: str = str(Path(sys.executable).with_name("lerobot-train"))
    lerobot_eval: str = str(Path(sys.executable).with_name("lerobot-eval"))
    accelerate: str = str(Path(sys.executable).with_name("accelerate"))
    torchrun: str = str(Path(sys.executable).with_name("torchrun"))

    # ----- paths --------------------------------------------------------------------------------------------
    def train_dir(self, config: str, suite: str, seed: int) -> Path:
        return self.runs_dir / "train" / config / suite / f"seed{seed}"

    def eval_dir(self, run: Run) -> Path:
        return eval_run_dir(self.runs_dir, run.config, run.suite, run.seed)

    def record_path(self, run: Run) -> Path:
        return self.runs_dir / "records" / run.config / run.suite / f"seed{run.seed}.json"

    def log_path(self, name: str, suite: str, seed: int, stage: str) -> Path:
        return run_log_path(self.runs_dir, name, suite, seed, stage)

    # ----- commands ---------------------------------------------------------------------------------------
    def launcher(self) -> list[str]:
        """`lerobot-train`, or for several processes LeRobot's multi-GPU path `accelerate launch --multi_gpu`; on
        the CPU `torchrun` (accelerate's Accelerator then runs DDP over gloo: `accelerate launch --cpu` starts one
        process only)."""
        procs = self.sweep.settings.accelerate_processes
        if procs == 1:
            return [self.lerobot_train]
        if self.sweep.settings.train_device == "cpu":
            return [self.torchrun, f"--nproc_per_node={procs}", self.lerobot_train]
        return [self.accelerate, "launch", "--multi_gpu", f"--num_processes={procs}", self.lerobot_train]

    def train_command(self, spec: ConfigSpec, suite: str, seed: int) -> list[str]:
        s = self.sweep.settings
        spec = self.at_selected_lr(spec, suite)
        dataset = s.datasets[suite]
        procs = s.accelerate_processes
        if s.batch_size % procs:
            raise SweepError(f"batch_size {s.batch_size} is not divisible by accelerate_processes {procs}.")
        return [
            *self.launcher(),
            *spec.policy_args(self.sweep.base_dir, suite),
            f"--dataset.repo_id={dataset['repo_id']}",
            *([f"--dataset.root={self.train_root(suite) or self._path(dataset['root'])}"]
              if dataset.get("root") else []),
            f"--output_dir={self.train_dir(spec.name, suite, seed)}",
            f"--job_name={spec.name}_{suite}_seed{seed}",
            f"--seed={seed}",
            f"--steps={self.sweep.steps_of(spec)}",
            f"--batch_size={s.batch_size // procs}",  # per process: the effective batch stays batch_size
            f"--save_freq={s.save_freq}",
            f"--policy.device={s.train_device}",
            "--policy.push_to_hub=false",
            "--wandb.enable=false",
            *s.train_args,
            *spec.train_args,
        ]

    def resume_command(self, train_dir: Path, suite: str) -> list[str]:
        """Resume from the last checkpoint, with its own train_config.json; a sweep that names a `train_root`
        points the resumed training at it (LeRobot lets command-line flags override a resumed config): the same
        samples without camera frames, for trainings started before the copy existed."""
        config = last_pretrained(train_dir) / "train_config.json"
        train_root = self.train_root(suite)
        return [*self.launcher(), f"--config_path={config}", "--resume=true",
                *([f"--dataset.root={train_root}"] if train_root else [])]

    def train_root(self, suite: str) -> Path | None:
        """The copy of `suite`'s dataset without camera frames that training reads, when the sweep names one."""
        train_root = self.sweep.settings.datasets[suite].get("train_root")
        return self._path(train_root) if train_root else None

    def eval_command(self, run: Run, checkpoint: Path) -> list[str]:
        s = self.sweep.settings
        spec = self.sweep.configs[run.config]
        return [
            self.lerobot_eval,
            f"--policy.path={checkpoint}",
            f"--policy.device={s.eval_device}",
            *_as_args(spec.eval_overrides, "policy"),
            *self.corruption_args(spec, run.suite),
            f"--env.type={s.env_type}",
            f"--env.task={run.suite}",
            f"--env.episode_length={s.episode_length}",
            f"--env.init_states={str(spec.init_states).lower()}",
            f"--eval.n_episodes={spec.n_episodes or s.n_episodes}",
            f"--eval.batch_size={s.eval_batch_size}",
            "--eval.use_async_envs=false",
            f"--seed={run.seed if spec.eval_seed is None else spec.eval_seed}",
            f"--output_dir={self.eval_dir(run)}",
            *s.eval_args,
            *spec.eval_args,
        ]

    def corruption_args(self, spec: ConfigSpec, suite: str) -> list[str]:
        """`--policy.er_corruption_*` for a corruption point: the unrelated episode from the source suite's dataset."""
        if spec.corruption is None:
            return []
        source = self.sweep.settings.datasets[self.sweep.corruption_source(spec, suite)]
        return _as_args({
            "er_corruption_channel": spec.corruption["channel"],
            "er_corruption_alpha": float(spec.corruption["alpha"]),
            "er_corruption_root": str(self._path(source["root"])),
            "er_corruption_episode": int(spec.corruption.get("episode", 0)),
        }, "policy")

    def _path(self, value: str) -> Path:
        path = Path(value)
        return path if path.is_absolute() else (self.sweep.base_dir / path).resolve()

    # ----- data ------------------------------------------------------------------------------------------
    def data_commands(self, suite: str) -> list[tuple[str, list[str]]]:
        """(stage, command) still to run to make `suite`'s datasets: its `root` from the `data` entry, then its
        `train_root` copy without camera frames; empty when they exist (or nothing says how to make them)."""
        predvla = [sys.executable, "-m", "lerobot_predvla.cli.main"]
        entry = self.sweep.settings.datasets[suite]
        commands = self.source_data_commands(suite, predvla)
        train_root = self.train_root(suite)
        if train_root and not (train_root / "meta" / "info.json").is_file():
            commands.append(("features_only", [
                *predvla, "features-only", "--dataset-root", str(self._path(entry["root"])),
                "--out", str(train_root), "--repo-id", entry["repo_id"],
            ]))
        return commands

    def source_data_commands(self, suite: str, predvla: list[str]) -> list[tuple[str, list[str]]]:
        """(stage, command) still to run to make `suite`'s `root` dataset from its `data` entry."""
        spec = self.sweep.settings.data.get(suite)
        if spec is None:
            return []
        dataset = self._path(self.sweep.settings.datasets[suite]["root"])
        if (dataset / "meta" / "info.json").is_file():
            return []
        hdf5, frontend = self._path(spec.hdf5), self._path(spec.frontend)
        commands = []
        missing = self.missing_demo_tasks(suite, spec, hdf5)
        shares = [missing[k::spec.workers] for k in range(min(spec.workers, len(missing)))]
        for k, share in enumerate(shares):
            commands.append(("demos" if len(shares) == 1 else f"demos.tasks{k}", [
                *predvla, "demos", "--suite", suite, "--tasks", ",".join(map(str, share)),
                "--per-task", str(spec.per_task), "--render-interval", str(spec.render_interval),
                "--seed", str(spec.demo_seed), "--init-noise", str(spec.init_noise),
                "--half-turn", spec.half_turn, "--hold-steps", str(spec.hold_steps), "--out", str(hdf5)]))
        if not (frontend / "metadata.json").is_file():
            commands.append(("frontend", [*predvla, "fit-frontend", "--hdf5-root", str(hdf5), "--suites", suite,
                                          "--vision-weights", spec.vision_weights, "--language-from",
                                          spec.language_from, "--frame-stride", str(spec.frame_stride),
                                          "--out", str(frontend)]))
        commands.append(("convert", [*predvla, "convert", "--hdf5-root", str(hdf5), "--suite", suite,
                                     "--frontend", str(frontend), "--out", str(dataset),
                                     "--repo-id", self.sweep.settings.datasets[suite]["repo_id"]]))
        return commands

    @staticmethod
    def missing_demo_tasks(suite: str, spec: DataSpec, hdf5: Path) -> list[int]:
        from lerobot_predvla.sims.libero.env import num_tasks, task_spec  # the simulator's tasks (sets MUJOCO_GL)
        from lerobot_predvla.sims.libero.hdf5_layout import task_file  # imports libero.env

        tasks = spec.tasks if spec.tasks is not None else range(num_tasks(suite))
        return [t for t in tasks if not task_file(hdf5, task_spec(suite, t)).is_file()]

    def make_data(self, suite: str) -> bool:
        """Run the missing data stages of `suite` (the `demos.tasks<k>` shares of `data.workers` at once),
        recording each one's command and wall time in `RUNS_DIR/data/<suite>.json`; False when one failed."""
        from concurrent.futures import ThreadPoolExecutor
        from itertools import groupby

        stages_file = self.runs_dir / "data" / f"{suite}.json"

        def run_stage(stage: str, command: list[str]) -> tuple[str, list[str], int, float]:
            start = time.monotonic()
            code = self.execute(command, self.log_path("data", suite, 0, stage))
            return stage, command, code, time.monotonic() - start

        for _, group in groupby(self.data_commands(suite), key=lambda item: item[0].split(".")[0]):
            group = list(group)
            with ThreadPoolExecutor(max_workers=len(group)) as pool:
                finished = list(pool.map(lambda item: run_stage(*item), group))
            stages = json.loads(stages_file.read_text()) if stages_file.is_file() else {}
            for stage, command, code, wall in finished:
                if code == 0:
                    stages[stage] = {"command": command, "wall_s": round(wall, 1)}
            atomic_write_json(stages_file, stages)
            failed = [(stage, code) for stage, _, code, _ in finished if code != 0]
            for stage, code in failed:
                print(f"predvla sweep: data stage {stage} of {suite} failed (exit {code}); see "
                      f"{self.log_path('data', suite, 0, stage)}", file=sys.stderr)
            if failed:
                return False
        return True

    # ----- running ----------------------------------------------------------------------------------------
    def write_plan(self, runs: list[Run], configs: list[str] | None = None) -> None:
        """`plan.json`: every run of the sweep and its configuration, so the report can mark missing runs.

        The runs already planned in RUNS_DIR are kept (those of configurations the sweep file still has): a later
        call restricted by `--seeds`, `--suites` or `--configs` adds the runs it runs (with `--configs`, only those
        configurations': `--configs X --seeds 1` plans no other configuration at seed 1) instead of replacing the
        plan. Only the call's `configs` (all when None) are described afresh; the others keep their earlier
        descriptions, so a call with `--n-episodes` or `--steps` does not rewrite the protocol of configurations it
        does not run. A configuration's own seeds, narrowed by `--seeds`, are described with the seeds planned
        before (as its runs are kept).
        """
        path = self.runs_dir / "plan.json"
        try:
            earlier = json.loads(path.read_text()) if path.is_file() else {"runs": [], "configs": {}}
            planned = [Run(**r) for r in earlier["runs"] if r["config"] in self.sweep.configs]
            described = dict(earlier.get("configs", {}))
        except (ValueError, KeyError, TypeError) as err:
            raise SweepError(f"{path}: expected a sweep plan with a list of runs {{config, suite, seed}} ({err}); "
                             "delete it to plan from the sweep file alone") from err
        runs = planned + [r for r in runs if r not in planned]
        fresh = set(configs or self.sweep.configs)

        def describe(name: str, spec: ConfigSpec) -> dict:
            if name not in fresh and name in described:
                return described[name]
            earlier_seeds = described.get(name, {}).get("seeds")
            if spec.seeds is None or not earlier_seeds:
                return asdict(spec)
            return {**asdict(spec), "seeds": sorted(set(spec.seeds) | set(earlier_seeds))}

        atomic_write_json(path, {
            "runs": [asdict(r) for r in runs],
            "configs": {name: describe(name, spec) for name, spec in self.sweep.configs.items()},
            "protocol": earlier["protocol"] if configs and "protocol" in earlier else {
                "n_episodes": self.sweep.settings.n_episodes, "episode_length": self.sweep.settings.episode_length},
        })

    def shard_units(
        self, configs: list[str] | None, shard: tuple[int, int]
    ) -> list[tuple[tuple[str, str, int], list[Run]]]:
        """This shard's training units: every n-th checkpoint, with all runs that evaluate it."""
        return [u for i, u in enumerate(self.sweep.units(self.sweep.runs(configs))) if i % shard[1] == shard[0]]

    def pending_commands(self, configs: list[str] | None, shard: tuple[int, int]) -> list[list[str]]:
        """The commands `run` would start now (for --dry-run); a resumed training shows its resume command."""
        commands, data_done, selected = [], set(), set()
        for (trained, suite, seed), unit_runs in self.shard_units(configs, shard):
            pending = [r for r in unit_runs if not self.record_path(r).is_file()]
            if not pending:
                continue
            out = self.train_dir(trained, suite, seed)
            if suite not in data_done and not (out / TRAIN_DONE_FILE).is_file():
                commands += [command for _, command in self.data_commands(suite)]
                data_done.add(suite)
            if (out / TRAIN_DONE_FILE).is_file():
                checkpoint = self.evaluable_checkpoint(json.loads((out / TRAIN_DONE_FILE).read_text()), out)
                if checkpoint is None:
                    continue
            else:
                if (trained, suite) not in selected:  # one selection serves every seed
                    commands += self.pending_lr_commands(self.sweep.configs[trained], suite)
                    selected.add((trained, suite))
                spec = self.sweep.configs[trained]
                commands.append(self.pending_train_command(spec, suite, seed))
                checkpoint = last = last_pretrained(out)
                if self.sweep.settings.publish:
                    checkpoint = self.publish_dir(spec, suite, seed)
                    commands.append(self.publish_command(checkpoint, last))
            commands += [command for run in pending for command in self.pending_eval_commands(run, checkpoint)]
        return commands

    def pending_train_command(self, spec: ConfigSpec, suite: str, seed: int) -> list[str]:
        """A training's resume command when it has a checkpoint, else its command from the start."""
        out = self.train_dir(spec.name, suite, seed)
        if (last_pretrained(out) / "train_config.json").is_file():
            return self.resume_command(out, suite)
        return self.train_command(spec, suite, seed)

    def pending_lr_commands(self, spec: ConfigSpec, suite: str) -> list[list[str]]:
        """The candidate trainings a learning-rate selection still needs (none once it has chosen)."""
        sweep = spec.lr_sweep
        if sweep is None or selection_path(self.runs_dir, spec.name, suite).is_file():
            return []
        candidates = [self.candidate_spec(spec, rate) for rate in sweep.rates
                      if not candidate_path(self.runs_dir, spec.name, suite, rate).is_file()]
        return [self.pending_train_command(c, suite, sweep.seed) for c in candidates
                if not (self.train_dir(c.name, suite, sweep.seed) / TRAIN_DONE_FILE).is_file()]

    def run(
        self, configs: list[str] | None = None, shard: tuple[int, int] = (0, 1), progress: bool = True
    ) -> dict[str, list[str]]:
        """Run (or skip) this shard's runs. Returns run keys by outcome: done, skipped, failed."""
        from tqdm import tqdm

        self.write_plan(self.sweep.runs(configs), configs)
        units = self.shard_units(configs, shard)
        outcome: dict[str, list[str]] = {"done": [], "skipped": [], "failed": []}
        bar = tqdm(total=sum(len(r) for _, r in units), desc=f"sweep shard {shard[0]}/{shard[1]}", disable=not progress)
        for (trained, suite, seed), unit_runs in units:
            pending = [r for r in unit_runs if not self.record_path(r).is_file()]
            outcome["skipped"] += [r.key for r in unit_runs if r not in pending]
            bar.update(len(unit_runs) - len(pending))
            if not pending:
                continue
            trained_spec = self.sweep.configs[trained]
            train_result = self.train(trained_spec, suite, seed)
            if train_result is not None and self.evaluable_checkpoint(
                    train_result, self.train_dir(trained, suite, seed)) is None:
                train_result = None
            for run in pending:
                bar.set_postfix_str(run.key)
                ok = train_result is not None and self.evaluate(run, train_result)
                outcome["done" if ok else "failed"].append(run.key)
                bar.update(1)
        bar.close()
        return outcome

    def trained_checkpoint(self, trained: dict) -> Path:
        """The checkpoint of a finished training (`TRAIN_DONE_FILE`), kept relative to RUNS_DIR so that a sweep
        directory moved to another machine, or pointed at a committed checkpoint, still finds it."""
        return (self.runs_dir / trained["checkpoint"]).resolve()

    def evaluable_checkpoint(self, trained: dict, out: Path) -> Path | None:
        """The checkpoint a finished training (`out`'s `TRAIN_DONE_FILE`) names, checked before its evaluations;
        None, with what to do on stderr, when it is gone: one left out of a copied or cloned RUNS_DIR must not turn
        into an evaluation error per task."""
        checkpoint = self.trained_checkpoint(trained)
        if (checkpoint / "model.safetensors").is_file():
            return checkpoint
        done = out / TRAIN_DONE_FILE
        print(f"predvla sweep: {done} names the checkpoint {checkpoint}, which has no model.safetensors. Restore "
              f"that checkpoint, or remove {done} to train it again: evaluations already recorded from the lost "
              "model keep their records (move those aside to evaluate the new model in their place)", file=sys.stderr)
        return None

    def train(self, spec: ConfigSpec, suite: str, seed: int, publish: bool = True) -> dict | None:
        """Train (or resume, or reuse) one checkpoint; None when lerobot-train (or its `train.publish`) failed.
        `publish=False`: never publish it (a learning-rate candidate)."""
        out = self.train_dir(spec.name, suite, seed)
        done = out / TRAIN_DONE_FILE
        if done.is_file():
            return json.loads(done.read_text())
        if not self.make_data(suite):  # the dataset is needed only to train: evaluations never read it
            return None
        if spec.lr_sweep is not None and self.select_lr(spec, suite) is None:
            return None
        last = last_pretrained(out)
        if (last / "train_config.json").is_file():
            command, resumed = self.resume_command(out, suite), True
        else:
            shutil.rmtree(out, ignore_errors=True)  # started but no checkpoint yet: lerobot-train needs a new dir
            command, resumed = self.train_command(spec, suite, seed), False
        start = time.monotonic()
        code = self.execute(command, self.log_path(spec.name, suite, seed, "train"))
        if code != 0 or not (last / "model.safetensors").is_file():
            print(f"predvla sweep: training {spec.name}/{suite}/seed{seed} failed (exit {code}); see "
                  f"{self.log_path(spec.name, suite, seed, 'train')}", file=sys.stderr)
            return None
        train_wall = round(time.monotonic() - start, 1)
        keep_every = self.sweep.settings.keep_every
        pruned = prune_checkpoints(out, keep_every) if keep_every else []
        published = self.publish_model(spec, suite, seed, last) if publish and self.sweep.settings.publish else None
        if published is False:
            return None
        result = {
            "checkpoint": os.path.relpath((published or last).resolve(), self.runs_dir.resolve()),
            "steps": self.sweep.steps_of(spec),
            "parameters": count_parameters(last / "model.safetensors"),
            "train_wall_s": train_wall,  # this call only: a resumed training's earlier calls are in its log
            "machine": machine(),
            "resumed": resumed,
            "command": command,
            "checkpoints_pruned": len(pruned),
        }
        if published:
            result["trained_checkpoint"] = os.path.relpath(last.resolve(), self.runs_dir.resolve())
        atomic_write_json(done, result)
        return result

    def publish_dir(self, spec: ConfigSpec, suite: str, seed: int) -> Path:
        return self._path(self.sweep.settings.publish.format(config=spec.name, suite=suite, seed=seed))

    @staticmethod
    def publish_command(dest: Path, last: Path) -> list[str]:
        return [sys.executable, "-m", "lerobot_predvla.cli.main", "push", str(last), os.path.relpath(dest),
                "--out", str(dest)]

    def publish_model(self, spec: ConfigSpec, suite: str, seed: int, last: Path) -> Path | bool:
        """`train.publish`: the final model of a training, as `predvla push --out` writes it, in its folder; False
        when that failed. A folder already there (a sweep stopped between the copy and the training record) is
        kept if it holds this training's weights, and refused otherwise (the run fails; nothing is overwritten)."""
        dest = self.publish_dir(spec, suite, seed)
        if dest.exists():
            if (dest / "model.safetensors").is_file() and filecmp.cmp(dest / "model.safetensors",
                                                                       last / "model.safetensors", shallow=False):
                return dest
            print(f"predvla sweep: train.publish: {dest} exists and does not hold the weights of {last}; move it "
                  "away or change train.publish.", file=sys.stderr)
            return False
        command = self.publish_command(dest, last)
        log = self.log_path(spec.name, suite, seed, "publish")
        code = self.execute(command, log)
        if code != 0 or not (dest / "model.safetensors").is_file():
            print(f"predvla sweep: publishing {spec.name}/{suite}/seed{seed} to {dest} failed (exit {code}); see "
                  f"{log}", file=sys.stderr)
            return False
        return dest

    # ----- learning-rate selection ---------------------------------------------------------------------------
    def candidate_spec(self, spec: ConfigSpec, rate: float) -> ConfigSpec:
        """The candidate training of `spec` at `rate`: its sweep's steps, episodes held out, nothing to select."""
        sweep = spec.lr_sweep
        return replace(spec, name=candidate_name(spec.name, rate), steps=sweep.steps, lr_sweep=None,
                       policy_overrides={**spec.policy_overrides, "optimizer_lr": float(rate)},
                       train_args=[*spec.train_args, *sweep.train_args()])

    def at_selected_lr(self, spec: ConfigSpec, suite: str) -> ConfigSpec:
        """`spec` with its chosen learning rate (a placeholder before the selection, for dry runs)."""
        if spec.lr_sweep is None:
            return spec
        path = selection_path(self.runs_dir, spec.name, suite)
        rate = json.loads(path.read_text())["chosen_lr"] if path.is_file() else PENDING_LR
        return replace(spec, policy_overrides={**spec.policy_overrides, "optimizer_lr": rate})

    def lr_candidate(self, spec: ConfigSpec, suite: str, rate: float) -> dict | None:
        """Train (or reuse) one candidate and read its held-out loss; None when its training failed other than by
        diverging (a re-run retries it)."""
        path = candidate_path(self.runs_dir, spec.name, suite, rate)
        if path.is_file():
            return json.loads(path.read_text())
        sweep, candidate = spec.lr_sweep, self.candidate_spec(spec, rate)
        log = self.log_path(candidate.name, suite, sweep.seed, "train")
        trained = self.train(candidate, suite, sweep.seed, publish=False)
        if trained is None:
            diverged = divergence(log)
            if diverged is None:
                return None
            result = {"lr": float(rate), "heldout_nll": None, "diverged": diverged}
        else:
            curve = heldout_losses(log)
            if sweep.steps not in curve:
                raise SweepError(f"{log}: no held-out loss at step {sweep.steps} (`step {sweep.steps}: eval_loss=`); "
                                 f"delete {self.train_dir(candidate.name, suite, sweep.seed)} to train the "
                                 "candidate again.")
            final = curve[sweep.steps]
            result = {"lr": float(rate), "heldout_nll": final if math.isfinite(final) else None,
                      "heldout_curve": {str(step): loss for step, loss in sorted(curve.items())},
                      "steps": trained["steps"], "train_wall_s": trained["train_wall_s"],
                      "checkpoint": trained["checkpoint"], "command": trained["command"]}
        atomic_write_json(path, result)
        return result

    def select_lr(self, spec: ConfigSpec, suite: str) -> float | None:
        """The learning rate of `spec` on `suite` chosen on held-out demonstrations (`lr_selection.py`), selecting
        it first if needed; None when a candidate's training failed."""
        path = selection_path(self.runs_dir, spec.name, suite)
        if path.is_file():
            return json.loads(path.read_text())["chosen_lr"]
        sweep = spec.lr_sweep
        candidates = {}
        for rate in sweep.rates:
            result = self.lr_candidate(spec, suite, rate)
            if result is None:
                return None
            candidates[float(rate)] = result
        try:
            chosen = choose({rate: result["heldout_nll"] for rate, result in candidates.items()})
        except ValueError as err:
            raise SweepError(f"configuration {spec.name} on {suite}: {err}") from err
        dataset = self.sweep.settings.datasets[suite]
        atomic_write_json(path, {
            "config": spec.name,
            "suite": suite,
            "criterion": CRITERION,
            "rates": [float(r) for r in sweep.rates],
            "steps": sweep.steps,
            "eval_split": sweep.eval_split,
            "seed": sweep.seed,
            "heldout_episodes": heldout_episodes(dataset["repo_id"], self._path(dataset["root"]), sweep.eval_split),
            "heldout_nll": {f"{rate:g}": result["heldout_nll"] for rate, result in candidates.items()},
            "chosen_lr": chosen,
            "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        })
        print(f"predvla sweep: {spec.name} on {suite}: optimizer_lr {chosen:g} chosen on held-out demonstrations; "
              f"see {path}", file=sys.stderr)
        return chosen

    def eval_parts(self, run: Run) -> list[tuple[Path, list[str]]]:
        """(output directory, extra lerobot-eval arguments) of each part of a run's evaluation: the whole suite
        at once, or one part per task with `eval.tasks`, each finished part kept when the run is redone."""
        out = self.eval_dir(run)
        tasks = self.sweep.settings.eval_tasks
        if tasks is None:
            return [(out, [])]
        return [(out / f"task{t}", [f"--env.task_ids=[{t}]"]) for t in tasks]

    def part_command(self, run: Run, checkpoint: Path, out: Path, extra: list[str]) -> list[str]:
        command = [*self.eval_command(run, checkpoint), *extra]
        command[command.index(f"--output_dir={self.eval_dir(run)}")] = f"--output_dir={out}"
        return command

    def pending_eval_commands(self, run: Run, checkpoint: Path) -> list[list[str]]:
        return [self.part_command(run, checkpoint, out, extra) for out, extra in self.eval_parts(run)
                if not (out / EVAL_INFO_FILE).is_file()]

    def evaluate_part(self, run: Run, command: list[str], out: Path, log: Path) -> bool:
        """One part of an evaluation (the whole suite or one task), skipped when its `eval_info.json` exists; its
        wall time is kept beside it."""
        if (out / EVAL_INFO_FILE).is_file():
            return True
        shutil.rmtree(out, ignore_errors=True)  # a killed evaluation is redone from scratch
        start = time.monotonic()
        code = self.execute(command, log)
        if code != 0 or not (out / EVAL_INFO_FILE).is_file():
            print(f"predvla sweep: evaluation {run.key} ({out.name}) failed (exit {code}); see {log}", file=sys.stderr)
            return False
        atomic_write_json(out / EVAL_WALL_FILE, {"eval_wall_s": round(time.monotonic() - start, 1)})
        return True

    def evaluate(self, run: Run, trained: dict) -> bool:
        """Evaluate a run part by part, `eval_workers` parts at once (each with its own log when several run), and
        write its record once every part has its `eval_info.json`."""
        from concurrent.futures import ThreadPoolExecutor

        spec = self.sweep.configs[run.config]
        parts = [(out, self.part_command(run, self.trained_checkpoint(trained), out, extra))
                 for out, extra in self.eval_parts(run)]
        workers = max(1, min(self.sweep.settings.eval_workers, len(parts)))
        log = self.log_path(run.config, run.suite, run.seed, "eval")

        def part_log(out: Path) -> Path:
            return log if workers == 1 else log.with_name(f"{log.stem}.{out.name}.log")

        with ThreadPoolExecutor(max_workers=workers) as pool:
            finished = list(pool.map(lambda part: self.evaluate_part(run, part[1], part[0], part_log(part[0])), parts))
        if not all(finished):
            return False
        tasks, commands, wall = {}, [command for _, command in parts], 0.0
        for out, _ in parts:
            try:
                tasks.update(parse_eval_info(out / EVAL_INFO_FILE))
            except EvalInfoError as err:
                raise SweepError(str(err)) from err
            wall_file = out / EVAL_WALL_FILE
            wall += json.loads(wall_file.read_text())["eval_wall_s"] if wall_file.is_file() else 0.0
        tasks = dict(sorted(tasks.items(), key=lambda kv: int(kv[0])))
        command = commands[0] if len(commands) == 1 else commands
        successes = sum(t["successes"] for t in tasks.values())
        episodes = sum(t["episodes"] for t in tasks.values())
        record = {
            "config": run.config,
            "group": spec.group,
            "label": spec.label,
            "compare_to": spec.compare_to,
            "pool_with": spec.pool_with,
            "branch": spec.branch,
            "corruption": spec.corruption,
            "eval_overrides": spec.eval_overrides,
            "init_states": spec.init_states,
            "eval_seed": run.seed if spec.eval_seed is None else spec.eval_seed,
            "checkpoint_from": spec.checkpoint_from,
            "suite": run.suite,
            "seed": run.seed,
            "steps": trained["steps"],
            "parameters": trained["parameters"],
            "tasks": tasks,
            "successes": successes,
            "episodes": episodes,
            "success_rate": 100.0 * successes / episodes,
            "n_episodes_per_task": spec.n_episodes or self.sweep.settings.n_episodes,
            "episode_length": self.sweep.settings.episode_length,
            "train_wall_s": trained["train_wall_s"],
            "eval_wall_s": round(wall, 1),  # summed over the parts: with several workers, more than the elapsed time
            "eval_workers": workers,
            "checkpoint": trained["checkpoint"],
            # the weights evaluated: a training redone in place leaves the path, not this (report.same_model)
            "model_sha256": sha256_file(self.trained_checkpoint(trained) / "model.safetensors"),
            "commands": {"train": trained["command"], "eval": command},
            "versions": versions(),
            "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        atomic_write_json(self.record_path(run), record)
        return True
