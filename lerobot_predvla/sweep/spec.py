"""The sweep file (YAML or JSON) of `predvla sweep`: its configurations, the sweep-wide settings, how datasets are
made, and the checks that run when it is loaded.

Every (configuration, suite, seed) of a sweep is one `Run`; `Sweep.runs` lists them and `Sweep.units` groups them
by the checkpoint they need (a training unit, the step `--shard i/n` splits a sweep by).
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from lerobot_predvla.columns import SUITES
from lerobot_predvla.lerobot_commands import policy_args
from lerobot_predvla.policies.recipe import NOT_RECIPE
from lerobot_predvla.sims.libero.object_shift import ShiftSpec
from lerobot_predvla.sims.libero.protocol import EVAL_ENV_TYPE, PAPER_EPISODE_LENGTH, PAPER_EPISODES_PER_TASK
from lerobot_predvla.sims.libero.variants import parse_variant
from lerobot_predvla.sweep.data_spec import DataSpec, data_problems
from lerobot_predvla.sweep.lr_selection import LRSweep, candidate_name

PAPER_TRAIN_STEPS = 30_000
PAPER_BATCH_SIZE = 32
# robustness: shown only in the report's robustness table (shifted objects, LIBERO-PRO / LIBERO-plus variants)
GROUPS = ("main", "baseline", "ladder", "ablation", "corruption", "robustness")
# The unrelated episode of a corruption run comes from another suite's dataset, so it is unrelated to every task
# of the evaluated suite (Section 4.4: "observations from an unrelated episode").
CORRUPTION_SOURCE = {
    "libero_spatial": "libero_goal",
    "libero_goal": "libero_object",
    "libero_object": "libero_spatial",
    "libero_10": "libero_spatial",
}
CORRUPTION_KEYS = {"channel", "alpha", "source_suite", "episode", "open_loop"}
# `object_shift` keys of a configuration -> the `predvla_libero` flags they become (lerobot_predvla/sims/libero/
# object_shift.py).
SHIFT_FLAGS = {"cm": "object_shift_cm", "target_cm": "target_shift_cm", "pattern": "object_shift_pattern",
               "directions": "object_shift_directions", "tolerance_cm": "shift_tolerance_cm"}


class SweepError(ValueError):
    """A malformed sweep file or an impossible request."""


def _recipe(fields: dict) -> dict:
    """The policy fields of `fields` that change what is computed (NOT_RECIPE left out)."""
    return {k: v for k, v in fields.items() if k not in NOT_RECIPE}


@dataclass
class ConfigSpec:
    """One configuration of a sweep file.

    Args:
        name: Unique name (a run directory component and the report's row label), e.g. `predvla`, `L3`, `A6`.
        group: Report section: main, baseline, ladder, ablation, corruption or robustness.
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
        object_shift: Evaluate with shifted objects (docs/evaluation.md): `{cm: 4, pattern: ring, directions: 20}`,
            optional `target_cm` and `tolerance_cm`; becomes `--env.object_shift_cm=4 --env.object_shift_pattern=ring
            ...` and is recorded. `{cm: 0}` is the unshifted cell of the same table.
        variant: Evaluate on a LIBERO-PRO or LIBERO-plus variant of each suite: `pro_temp_x0.1`, `pro_swap`,
            `plus_language_3`, ... (`--env.task=<suite>_<variant>`); recorded. Configurations with `object_shift` or
            `variant` make `predvla report`'s robustness table, one row per label.
        pool_with: The configuration this one extends with further training seeds (the same model and evaluation,
            e.g. at fewer episodes per task: the same trained configuration, `init_states` and `eval_overrides` but
            for fields of where or how fast they compute): `predvla report` adds a row over the union of their seeds
            and pools their paired episodes. With `compare_to` on both, this one's must pool with the other's (open
            loop on seeds 1-2 against error regression on seeds 1-2 pools with open loop on seed 0 against error
            regression on seed 0).
        pool_sets: The configurations that make this one's paired comparison (its `compare_to`) on other evaluation
            sets: each evaluates the model this one evaluates, in its mode, against the model and mode of this one's
            `compare_to`, on another set (randomised resets, shifted objects, ...). `predvla report` adds one paired
            comparison over all their episode pairs ("pooled over E1-E3": `olt_open_loop` with `pool_sets:
            [olt_open_loop_resets, olt_open_loop_shifted]`, docs/research/demonstrations.md).
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
    pool_sets: list[str] | None = None
    object_shift: dict | None = None
    variant: str | None = None

    def __post_init__(self) -> None:
        if isinstance(self.lr_sweep, dict):  # as read from a sweep file
            self.lr_sweep = LRSweep(**self.lr_sweep)

    def env_task(self, suite: str) -> str:
        """`--env.task` of this configuration's evaluation on `suite`: the suite, or its variant."""
        return suite if self.variant is None else f"{suite}_{self.variant}"

    def shift_args(self) -> list[str]:
        """`--env.<flag>=<value>` of `object_shift`."""
        return [f"--env.{SHIFT_FLAGS[k]}={v}" for k, v in (self.object_shift or {}).items()]

    def shift_problem(self) -> str | None:
        """Why `object_shift` is malformed, or None."""
        if not isinstance(self.object_shift, dict) or "cm" not in self.object_shift:
            return f"expected a mapping with `cm` and optional {sorted(set(SHIFT_FLAGS) - {'cm'})}"
        unknown = sorted(set(self.object_shift) - set(SHIFT_FLAGS))
        if unknown:
            return f"unknown keys {unknown}; expected {sorted(SHIFT_FLAGS)}"
        shift = {k: v for k, v in self.object_shift.items() if k != "cm"}
        try:
            ShiftSpec(object_cm=self.object_shift["cm"], **shift)
        except (TypeError, ValueError) as err:
            return str(err)
        return None if self.init_states else "shifted objects start from the official init states (init_states: true)"

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
        return policy_args(policy_type, {**fields, **self.policy_overrides, **self.suite_overrides.get(suite, {})})


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


@dataclass(frozen=True)
class Run:
    config: str
    suite: str
    seed: int

    @property
    def key(self) -> str:
        return f"{self.config}/{self.suite}/seed{self.seed}"


TOP_LEVEL_KEYS = ("seeds", "suites", "datasets", "data", "train", "eval", "configs")


def _read_mapping(path: Path) -> dict:
    text = path.read_text()
    raw = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    if not isinstance(raw, dict):
        raise SweepError(f"{path}: expected a mapping with a non-empty `configs` list.")
    return raw


def _extended(path: Path, raw: dict) -> dict:
    """`extends: <file>`: every setting but `configs` comes from a sweep file in the same folder, so a second screen
    keeps the first one's protocol by construction (its relative paths mean the same in both files)."""
    base_name = raw["extends"]
    if not isinstance(base_name, str) or Path(base_name).name != base_name:
        raise SweepError(f"{path}: `extends` must name a sweep file in the same folder, got {base_name!r}.")
    own = sorted(set(raw) - {"extends", "configs"})
    if own:
        raise SweepError(
            f"{path}: a file with `extends` takes every setting from {base_name}; remove its own keys {own}."
        )
    base_path = path.parent / base_name
    if not base_path.is_file():
        raise SweepError(f"{path}: `extends`: sweep file {base_path} not found.")
    base = _read_mapping(base_path)
    if "extends" in base:
        raise SweepError(f"{path}: `extends`: {base_path} extends another file itself; name that file instead.")
    return {**{k: v for k, v in base.items() if k != "configs"}, "configs": raw["configs"]}


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
        raw = _read_mapping(path)
        if not raw.get("configs"):
            raise SweepError(f"{path}: expected a mapping with a non-empty `configs` list.")
        unknown = set(raw) - set(TOP_LEVEL_KEYS) - {"extends"}
        if unknown:
            raise SweepError(f"{path}: unknown top-level keys {sorted(unknown)}.")
        if "extends" in raw:
            raw = _extended(path, raw)
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
            raise SweepError(
                f"{path}: train.keep_every must be a positive multiple of train.save_freq "
                f"({settings.save_freq}), got {settings.keep_every}."
            )
        if settings.publish is not None:
            try:
                settings.publish.format(config="c", suite="s", seed=0)
            except (KeyError, IndexError, ValueError) as err:
                raise SweepError(
                    f"{path}: train.publish {settings.publish!r}: expected a folder with only {{config}}, "
                    f"{{suite}} and {{seed}} to fill in ({err!r})."
                ) from err
        problems = data_problems(settings.data, path.parent)
        if problems:
            raise SweepError(f"{path}: {problems[0]}")
        sweep = cls(settings, {}, path.parent)
        for spec in configs:
            if spec.name in sweep.configs:
                raise SweepError(f"{path}: configuration name {spec.name!r} appears twice.")
            for name, own in (("suites", spec.suites), ("seeds", spec.seeds)):
                # In the file only: `--seeds` / `--suites` may leave a configuration none of its own (not run).
                if own is not None and not own:
                    raise SweepError(
                        f"{path}: configuration {spec.name}: `{name}` is empty; leave it out to use the sweep's {name}."
                    )
            sweep.configs[spec.name] = spec
        sweep.validate(path)
        return sweep

    def validate(self, where: Path) -> None:
        # Every reference first: the checks below follow them across configurations (a pool's compare_to's).
        for spec in self.configs.values():
            if spec.group not in GROUPS:
                raise SweepError(f"{where}: configuration {spec.name}: group {spec.group!r} is not one of {GROUPS}.")
            for ref in (spec.checkpoint_from, spec.compare_to, spec.pool_with,
                        *(spec.pool_sets if isinstance(spec.pool_sets, list) else [])):
                if ref is not None and ref not in self.configs:
                    raise SweepError(f"{where}: configuration {spec.name} refers to unknown configuration {ref!r}.")
        for spec in self.configs.values():
            if spec.checkpoint_from and (spec.train_args or spec.policy_overrides or spec.suite_overrides):
                raise SweepError(
                    f"{where}: configuration {spec.name} evaluates {spec.checkpoint_from}'s checkpoints; "
                    "give it eval_overrides/eval_args only."
                )
            if spec.checkpoint_from and self.configs[spec.checkpoint_from].checkpoint_from:
                raise SweepError(f"{where}: configuration {spec.name}: checkpoint_from must name a trained config.")
            if spec.pool_with is not None:
                self.validate_pool(spec, where)
            if spec.pool_sets is not None:
                self.validate_set_pool(spec, where)
            if spec.corruption is not None:
                self.validate_corruption(spec, where)
            if spec.lr_sweep is not None:
                self.validate_lr_sweep(spec, where)
            problem = None if spec.object_shift is None else spec.shift_problem()
            if problem:
                raise SweepError(f"{where}: configuration {spec.name}: object_shift {spec.object_shift!r}: {problem}.")
            for suite in self.suites_of(spec) if spec.variant is not None else []:
                if parse_variant(spec.env_task(suite)) is None:
                    raise SweepError(
                        f"{where}: configuration {spec.name}: variant {spec.variant!r} is not a LIBERO-PRO or "
                        f"LIBERO-plus variant name (pro_<folder>, e.g. pro_temp_x0.1, or plus_<variant>, e.g. "
                        f"plus_language_3; docs/evaluation.md)."
                    )
            for suite, value in spec.paper.items():
                numbers = value if isinstance(value, list) else [value]
                if (
                    suite not in SUITES
                    or not 1 <= len(numbers) <= 2
                    or not all(isinstance(x, int | float) for x in numbers)
                ):
                    raise SweepError(
                        f"{where}: configuration {spec.name}: `paper` maps a suite of {SUITES} to a "
                        f"success (%) or [mean, std]; got {suite}: {value!r}."
                    )
            unknown = set(self.suites_of(spec)) - set(SUITES)
            if unknown:
                raise SweepError(f"{where}: configuration {spec.name}: unknown suites {sorted(unknown)}; use {SUITES}.")
            missing = [s for s in self.suites_of(spec) if s not in self.settings.datasets]
            if missing:
                raise SweepError(f"{where}: `datasets` has no entry (repo_id, root) for suites {missing}.")
        pooled = [name for spec in self.configs.values() for name in spec.pool_sets or []]
        twice = sorted({name for name in pooled if pooled.count(name) > 1})
        if twice:
            raise SweepError(f"{where}: configurations {twice} are listed in more than one `pool_sets`.")
        for suite in self.settings.data:
            if not self.settings.datasets.get(suite, {}).get("root"):
                raise SweepError(f"{where}: `data` makes {suite}'s dataset, so `datasets.{suite}` needs a `root`.")
        for suite, entry in self.settings.datasets.items():
            if entry.get("train_root") and not entry.get("root"):
                raise SweepError(
                    f"{where}: `datasets.{suite}.train_root` is copied from a local dataset: give its `root` too."
                )

    def validate_pool(self, spec: ConfigSpec, where: Path) -> None:
        target = self.configs[spec.pool_with]
        problem = None
        if target.name == spec.name or target.pool_with is not None:
            problem = "must name a configuration that pools with none (the row that gathers the seeds)"
        elif (
            (spec.checkpoint_from or spec.name) != (target.checkpoint_from or target.name)
            or _recipe(spec.eval_overrides) != _recipe(target.eval_overrides)
            or spec.init_states != target.init_states
        ):
            problem = (
                f"it must evaluate the model {target.name} evaluates, as it does (checkpoint_from, "
                "eval_overrides but for where or how fast they compute, init_states)"
            )
        elif spec.compare_to and target.compare_to and self.configs[spec.compare_to].pool_with != target.compare_to:
            # One of them without compare_to is fine: the pool's paired episodes are then the other's alone.
            problem = (
                f"its compare_to {spec.compare_to!r} must pool with {target.compare_to!r}, what "
                f"{target.name} compares to, so that the paired episodes pool"
            )
        if problem:
            raise SweepError(f"{where}: configuration {spec.name}: pool_with {spec.pool_with!r}: {problem}.")

    def validate_set_pool(self, spec: ConfigSpec, where: Path) -> None:
        """`pool_sets`: every configuration listed makes `spec`'s paired comparison, each on its own evaluation set."""

        def mode(c: ConfigSpec) -> tuple:  # the model evaluated and how (fields of where or how fast aside)
            return c.checkpoint_from or c.name, _recipe(c.eval_overrides), c.corruption

        def evaluation_set(c: ConfigSpec) -> tuple:
            return c.init_states, c.eval_seed, repr(c.object_shift), c.variant, tuple(sorted(c.eval_args))

        problem = None
        if not isinstance(spec.pool_sets, list) or not spec.pool_sets:
            problem = "expected a non-empty list of configuration names"
        elif spec.compare_to is None:
            problem = "it pools paired comparisons, so it needs a compare_to"
        for name in spec.pool_sets if problem is None else []:
            other = self.configs[name]
            if name == spec.name or other.pool_sets:
                problem = f"{name}: list other configurations, which list none themselves"
            elif (other.compare_to is None or mode(other) != mode(spec)
                  or mode(self.configs[other.compare_to]) != mode(self.configs[spec.compare_to])):
                problem = (f"{name} must make the comparison {spec.name} makes: the model {mode(spec)[0]} evaluated "
                           f"as {spec.name} evaluates it (checkpoint_from, eval_overrides but for where or how fast "
                           f"they compute), with a compare_to evaluated as {spec.compare_to!r} is")
            if problem:
                break
        sets = [evaluation_set(self.configs[n]) for n in [spec.name, *spec.pool_sets]] if problem is None else []
        if len(set(sets)) < len(sets):
            problem = ("two of its configurations evaluate on the same set (init_states, eval_seed, object_shift, "
                       "variant, eval_args); pool further seeds with pool_with")
        if problem:
            raise SweepError(f"{where}: configuration {spec.name}: pool_sets {spec.pool_sets!r}: {problem}.")

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
            raise SweepError(
                f"{where}: configuration {spec.name}: corruption needs channel (vision or proprio) and "
                f"alpha, got {c!r}."
            )
        unknown = sorted(set(c) - CORRUPTION_KEYS)
        if unknown:
            raise SweepError(
                f"{where}: configuration {spec.name}: unknown corruption keys {unknown}; expected "
                f"{sorted(CORRUPTION_KEYS)}."
            )
        if not 0.0 <= float(c["alpha"]) <= 1.0:
            raise SweepError(f"{where}: configuration {spec.name}: corruption alpha {c['alpha']} is not in [0, 1].")
        sources = {self.corruption_source(spec, suite) for suite in self.suites_of(spec)}
        missing = sorted(sources - set(self.settings.datasets))
        if missing:
            raise SweepError(
                f"{where}: configuration {spec.name}: the corruption source suites {missing} have no "
                "entry in `datasets`."
            )
        remote = sorted(s for s in sources if not self.settings.datasets[s].get("root"))
        if remote:
            raise SweepError(
                f"{where}: configuration {spec.name}: the corruption source datasets of {remote} need a local `root`."
            )

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
    """ "i/n" with 0 <= i < n."""
    try:
        index, count = (int(x) for x in text.split("/"))
    except ValueError as err:
        raise SweepError(f"--shard {text!r}: expected i/n, e.g. 0/4.") from err
    if count < 1 or not 0 <= index < count:
        raise SweepError(f"--shard {text!r}: need 0 <= i < n.")
    return index, count
