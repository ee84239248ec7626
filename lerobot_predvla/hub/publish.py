"""Publishing PredVLA checkpoints on the Hugging Face Hub with the model card of `hub/predvla_card.md`.

Two routes end in `upload_files` (one `HfApi.create_commit`):
- `lerobot-train ... --policy.push_to_hub=true --policy.repo_id=...`: `PredVLAPolicy.push_model_to_hub` calls
  `push_trained_policy` at the end of training (LeRobot then pushes the processors in their own commits);
- `predvla push CHECKPOINT_DIR REPO_ID`: `push_checkpoint` publishes a saved checkpoint in one commit.

What is published: `config.json`, `model.safetensors`, `train_config.json`, the processors
(`policy_preprocessor*.json/.safetensors`, `policy_postprocessor*`, which carry the front-end artefact), the
artefact itself as `predvla_frontend/` when available, `README.md` (the card) and `sha256_manifest.json` (the
SHA-256 of every file of the commit, verified on loading). Never the training
posteriors (`posterior_store.safetensors`) nor `training_state/` (optimizer, scheduler, RNG).
"""

import dataclasses
import importlib.metadata
import importlib.resources
import json
import re
import shutil
import tempfile
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path
from string import Template

from huggingface_hub import CommitOperationAdd, HfApi
from lerobot.configs import PreTrainedConfig
from lerobot.utils.constants import POLICY_PREPROCESSOR_DEFAULT_NAME

from lerobot_predvla.experiments.report import SUMMARY_FILE, load_summary
from lerobot_predvla.frontend.artefact import METADATA_FILE, TENSORS_FILE
from lerobot_predvla.libero.protocol import EVAL_ENV_TYPE, PAPER_EPISODE_LENGTH, PAPER_EPISODES_PER_TASK, SUITES
from lerobot_predvla.policies import POLICY_TYPES
from lerobot_predvla.policies.common.cached_features import FRONTEND_META_DIR
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PREDICTIVE_RUNGS
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE
from lerobot_predvla.utils.checkpoints import REQUIRED_FILES, find_pretrained
from lerobot_predvla.utils.manifest import MANIFEST_FILE, manifest_text
from lerobot_predvla.utils.parameters import count_parameters
from lerobot_predvla.utils.versions import package_version

# Package data of lerobot_predvla.hub (pyproject package-data), read with importlib.resources.
CARD_TEMPLATE = importlib.resources.files("lerobot_predvla.hub") / "predvla_card.md"
CARD_FILE = "README.md"
FRONTEND_DIR = "predvla_frontend"  # the artefact's folder inside a checkpoint and a Hub repo
PUSH_PATTERNS = ("*.safetensors", "*.json", "*.yaml", "*.md")  # what LeRobot's own push uploads
# A saved folder's manifest lists that folder (posterior store included); each publishing route writes the manifest
# of what it publishes instead.
NEVER_PUSHED = (POSTERIOR_STORE_FILE, MANIFEST_FILE)
TAGS = ("robotics", "lerobot", "predvla", "libero")
PREDICTIVE_TAG = "predictive-coding"  # PredVLA and the ladder rungs that keep its predictive network
# Frozen encoders (counted once: torchvision resnet18 without `fc`; sentence-transformers all-MiniLM-L6-v2).
RESNET18_BACKBONE_PARAMS = 11_176_512
MINILM_PARAMS = 22_713_216
FRONTEND_STEP = "predvla_frontend_processor"
PREPROCESSOR_FILE = f"{POLICY_PREPROCESSOR_DEFAULT_NAME}.json"
MACHINE_FIELDS = ("frontend_dir", "device")  # policy config fields that name the training machine's resources
# Config fields that hold the paper's training length and batch, not this run's (the card's Training data has those).
PAPER_ONLY_FIELDS = ("train_steps", "train_batch_size")
PAPER_ONLY_NOTE = " (the paper's value; this run's: Training data)"
_LEFTOVER = re.compile(r"\$\{?[A-Za-z_][A-Za-z0-9_]*\}?|\{\{|\}\}")
_FEATURE_MEANING = {
    "observation.vision_features": "ResNet18 features of each camera, PCA per camera (cached or computed by the "
    "front end)",
    "observation.language_features": "all-MiniLM-L6-v2 instruction embedding, PCA",
}
# Meanings of the state and action by size: LIBERO's layouts; any other robot's are the dataset's own.
_SIZED_MEANING = {
    ("observation.state", 9): "proprioception: joint positions (7) + gripper (2)",
    ("observation.state", 8): "proprioception: end-effector position (3) + axis-angle (3) + gripper (2)",
    ("action", 7): "delta end-effector action (LIBERO, 7)",
}


def feature_meaning(key: str, feature: dict) -> str:
    """What a policy input or output is, for the card's table."""
    sized = _SIZED_MEANING.get((key, int(feature["shape"][0])))
    return _FEATURE_MEANING.get(key) or sized or f"the training dataset's `{key}` ({feature['type'].lower()})"


class HubError(ValueError):
    """A checkpoint or input that cannot be published as asked."""


# ----- files ---------------------------------------------------------------------------------------------
def pretrained_dir(checkpoint: Path) -> Path:
    """The `pretrained_model` directory of a checkpoint (or the directory itself when it holds the weights)."""
    found = find_pretrained(checkpoint)
    if found is not None:
        return found
    raise HubError(
        f"{checkpoint}: not a checkpoint; expected {' and '.join(REQUIRED_FILES)} in it or in its "
        "pretrained_model/ (e.g. outputs/RUN/checkpoints/last)."
    )


def publishable_files(directory: Path) -> dict[str, Path]:
    """Files of a saved policy that go to the Hub, keyed by their path in the repository."""
    files = {}
    for path in sorted(Path(directory).rglob("*")):
        rel = path.relative_to(directory).as_posix()
        if (
            path.is_file()
            and any(fnmatch(path.name, pattern) for pattern in PUSH_PATTERNS)
            and path.name not in NEVER_PUSHED
            and not any(part.startswith(".") for part in Path(rel).parts)  # temporary files of atomic writes
            and not rel.startswith("training_state/")
        ):
            files[rel] = path
    return files


def frontend_source(pretrained: Path, dataset_root: Path | None, override: Path | None) -> Path | None:
    """The artefact directory to publish: `override`, the checkpoint's own copy, or the dataset's copy."""
    if override is not None:
        if not (override / METADATA_FILE).is_file() or not (override / TENSORS_FILE).is_file():
            raise HubError(f"--frontend {override}: expected {METADATA_FILE} and {TENSORS_FILE} in it.")
        return override
    for candidate in (pretrained / FRONTEND_DIR, dataset_root / FRONTEND_META_DIR if dataset_root else None):
        if candidate is not None and (candidate / METADATA_FILE).is_file() and (candidate / TENSORS_FILE).is_file():
            return candidate
    return None


def read_json(files: dict[str, Path | bytes], name: str) -> dict:
    """A JSON file about to be published, from its path or from the bytes that replace it."""
    source = files[name]
    return json.loads(source if isinstance(source, bytes) else source.read_text())


def without_machine_paths(files: dict[str, Path]) -> dict[str, Path | bytes]:
    """The files as every route publishes them: the training machine's paths and device cleared from the configs.

    `frontend_dir` (the artefact is published beside the weights and inside the preprocessor), the dataset root and
    the output directory name places on the training machine only; loading ignores them once they are None. The
    device is the training machine's too. LeRobot keeps a stored device that is available and picks the best
    available one when it is None: `config.json`'s when loading the policy (`--policy.path`, `from_pretrained`), and
    `train_config.json`'s policy device when training from it (`lerobot-train --config_path=...`, `--resume`). Both
    are cleared. The processors keep theirs: a device step needs a device (None fails to load); `lerobot-eval`,
    `lerobot-rollout`, `lerobot-train` and LeRobot's policy server replace the preprocessor's with the policy's, and
    the postprocessor's `cpu` is where actions go (the environment or robot), not where the policy trained. The
    front-end step's `device` of older checkpoints is ignored when loading (the encoders follow the images) and
    dropped.
    """
    published: dict[str, Path | bytes] = dict(files)
    if "config.json" in files:
        config = read_json(files, "config.json")
        published["config.json"] = json.dumps(
            {**config, **{k: None for k in MACHINE_FIELDS if k in config}}, indent=4).encode()
    if "train_config.json" in files:
        train_cfg = read_json(files, "train_config.json")
        train_cfg["output_dir"] = None
        if isinstance(train_cfg.get("dataset"), dict):
            train_cfg["dataset"]["root"] = None
        if isinstance(train_cfg.get("policy"), dict):
            train_cfg["policy"].update({k: None for k in MACHINE_FIELDS if k in train_cfg["policy"]})
        published["train_config.json"] = json.dumps(train_cfg, indent=4).encode()
    if PREPROCESSOR_FILE in files:
        preprocessor = read_json(files, PREPROCESSOR_FILE)
        for step in preprocessor.get("steps", []):
            if step.get("registry_name") == FRONTEND_STEP:
                step.get("config", {}).pop("device", None)
        published[PREPROCESSOR_FILE] = json.dumps(preprocessor, indent=2).encode()  # LeRobot's layout
    return published


def frontend_metadata(files: dict[str, Path | bytes]) -> dict | None:
    """The artefact's `frontend.json`, from the published folder or from the preprocessor's front-end step."""
    if f"{FRONTEND_DIR}/{METADATA_FILE}" in files:
        return read_json(files, f"{FRONTEND_DIR}/{METADATA_FILE}")
    if PREPROCESSOR_FILE in files:
        for step in read_json(files, PREPROCESSOR_FILE).get("steps", []):
            if step.get("registry_name") == FRONTEND_STEP and step.get("config", {}).get("artefact"):
                return step["config"]["artefact"]
    return None


# ----- model card ------------------------------------------------------------------------------------------
@dataclass
class DatasetSummary:
    repo_id: str
    episodes: int
    frames: int
    fps: int
    tasks: list[str]

    @classmethod
    def from_meta(cls, meta) -> "DatasetSummary":
        return cls(meta.repo_id, meta.total_episodes, meta.total_frames, meta.fps, [str(t) for t in meta.tasks.index])

    @classmethod
    def from_root(cls, repo_id: str, root: Path) -> "DatasetSummary | None":
        """Read `meta/info.json` and `meta/tasks.parquet` of a local dataset; None when it is not here."""
        info = Path(root) / "meta" / "info.json"
        if not info.is_file():
            return None
        from lerobot.datasets import LeRobotDatasetMetadata

        return cls.from_meta(LeRobotDatasetMetadata(repo_id, root=root))


def _format_value(value) -> str:
    if isinstance(value, list | tuple):
        return "(" + ", ".join(_format_value(v) for v in value) + ")"
    if isinstance(value, float):
        return f"{value:g}"
    return f"`{value}`" if isinstance(value, str) else str(value)


def _suite_of(dataset_repo_id: str) -> str | None:
    return next((s for s in sorted(SUITES, key=len, reverse=True) if s in dataset_repo_id), None)


def eval_command(policy_path: str, suite: str, episode_length: int = PAPER_EPISODE_LENGTH,
                 episodes_per_task: int = PAPER_EPISODES_PER_TASK) -> str:
    """`lerobot-eval` of `policy_path` (a Hub repo or a local directory) from the official init states, the paper's
    protocol by default; LeRobot picks the device."""
    return (
        f"lerobot-eval --policy.path={policy_path} --env.type={EVAL_ENV_TYPE} --env.task={suite} "
        f"--env.episode_length={episode_length} --eval.n_episodes={episodes_per_task} "
        "--eval.batch_size=1 --eval.use_async_envs=false --output_dir=outputs/eval"
    )


def eval_protocol(main: dict | None) -> str:
    """What the card's evaluation command runs, and the paper's protocol where it differs."""
    paper = (f"the paper's protocol: {PAPER_EPISODES_PER_TASK} rollouts per task from the official LIBERO initial "
             f"states, each capped at {PAPER_EPISODE_LENGTH} control steps")
    if main is None or (main["n_episodes_per_task"], main["episode_length"]) == (PAPER_EPISODES_PER_TASK,
                                                                                  PAPER_EPISODE_LENGTH):
        return paper[0].upper() + paper[1:] + "."
    return (f"It reproduces the evaluation of the results below with this checkpoint's configuration: "
            f"{main['n_episodes_per_task']} rollouts per task from the official LIBERO initial states, each capped at "
            f"{main['episode_length']} control steps. For {paper}, pass `--env.episode_length={PAPER_EPISODE_LENGTH} "
            f"--eval.n_episodes={PAPER_EPISODES_PER_TASK}`.")


def _official(record: dict) -> bool:
    return record.get("init_states", True) is not False


def main_record(records: list[dict], config: dict) -> dict | None:
    """The evaluation a card's command reproduces: the checkpoint as published (no inference override), from the
    official init states, the most episodes first."""
    plain = [r for r in records if _official(r) and not inference_settings(r, config)]
    return max(plain, key=lambda r: (r["episodes"], -int(r["episode_length"])), default=None)


def _rate(record: dict) -> str:
    return f"{record['successes']}/{record['episodes']} ({100 * record['successes'] / record['episodes']:.1f}%)"


def result_limitations(records: list[dict], baselines: list[dict], config: dict) -> str:
    """Limitation lines that the checkpoint's own evaluations show: error regression against exact open loop on the
    same starts, and the behaviour-cloning baselines trained on the same data in the same sweep."""
    main = main_record(records, config)
    if main is None:
        return ""

    def same_protocol(r: dict) -> bool:
        return _official(r) and (r["episode_length"], r["n_episodes_per_task"]) == (
            main["episode_length"], main["n_episodes_per_task"])

    protocol = (f"{main['n_episodes_per_task']} episodes per task from the official init states, "
                f"{main['episode_length']}-step cap")
    lines = []
    open_loop = [r for r in records if same_protocol(r)
                 and {k: str(v) for k, v in inference_settings(r, config).items()} == {"er_iterations": "0"}]
    if config.get("type") == "predvla" and config.get("er_iterations", 0) and open_loop:
        ahead = main["successes"] - open_loop[0]["successes"]
        verdict = (f"{ahead} more than" if ahead > 0 else "as many as" if ahead == 0 else f"{-ahead} fewer than")
        from lerobot_predvla.experiments.headline import PAPER_OBJECT

        lead = PAPER_OBJECT["error_regression"][0] - PAPER_OBJECT["open_loop"][0]
        lines.append(f"- Error regression succeeds in {_rate(main)} episodes, {verdict} exact open loop "
                     f"(`--policy.er_iterations=0`: {_rate(open_loop[0])}), {protocol}; the paper reports error "
                     f"regression {lead:.2f} points ahead of exact open loop on libero_object.")
    bc = [r for r in baselines if same_protocol(r) and r["results"] == main["results"]]
    if bc and config.get("type") in ("predvla", "predvla_ladder"):
        ahead = [r for r in bc if r["successes"] > main["successes"]]
        listed = ", ".join(f"{r.get('label', r['config'])} {_rate(r)}" for r in sorted(bc, key=lambda r: r["config"]))
        lines.append(f"- Behaviour-cloning baselines trained on the same demonstrations in the same sweep "
                     f"(`{main['results']}`), {protocol}: {listed}; {len(ahead)} of {len(bc)} ahead of this "
                     "checkpoint.")
    return "".join(line + "\n" for line in lines)


# ----- evaluation records of a checkpoint -----------------------------------------------------------------
def _flag(command: list[str], name: str) -> str | None:
    return next((w.split("=", 1)[1] for w in command if w.startswith(f"{name}=")), None)


def training_processes(command: list[str]) -> int:
    """Processes of a recorded training command (`torchrun --nproc_per_node=N`, `accelerate --num_processes=N`)."""
    value = _flag(command, "--nproc_per_node") or _flag(command, "--num_processes")
    return int(value) if value else 1


def evaluation_records(checkpoint: Path, results_root: Path) -> list[dict]:
    """The `predvla sweep` run records under `results_root/*/runs/records/` that evaluated `checkpoint`: those whose
    `checkpoint` is this directory, and those whose training (job name, dataset and seed) is the one its
    `train_config.json` records (a checkpoint copied out of a sweep's runs directory)."""
    checkpoint = Path(checkpoint).resolve()
    train_cfg_path = checkpoint / "train_config.json"
    train_cfg = json.loads(train_cfg_path.read_text()) if train_cfg_path.is_file() else {}
    found = []
    for path in sorted(Path(results_root).glob("*/runs/records/*/*/seed*.json")):
        record = json.loads(path.read_text())
        runs_dir = path.parents[3]
        recorded = record.get("checkpoint")
        train = (record.get("commands") or {}).get("train") or []
        same_dir = recorded is not None and (runs_dir / recorded).resolve() == checkpoint
        same_training = bool(train_cfg) and (
            _flag(train, "--job_name") == train_cfg.get("job_name")
            and _flag(train, "--dataset.repo_id") == train_cfg.get("dataset", {}).get("repo_id")
            and int(record["seed"]) == train_cfg.get("seed"))
        if same_dir or same_training:
            found.append({**record, "results": str(runs_dir.parent.relative_to(Path(results_root).parent))})
    return found


def baseline_records(records: list[dict], results_root: Path) -> list[dict]:
    """The behaviour-cloning baselines' run records (`group: baseline`) in the sweeps that evaluated a checkpoint
    (`records`, from `evaluation_records`): trained on the same data."""
    found = []
    for folder in sorted({r["results"] for r in records}):
        for path in sorted((Path(results_root).parent / folder / "runs" / "records").glob("*/*/seed*.json")):
            record = json.loads(path.read_text())
            if record.get("group") == "baseline":
                found.append({**record, "results": folder})
    return found


def _frontend_section(meta: dict | None) -> tuple[str, str]:
    """(Markdown description, number of PCA values) of the artefact."""
    if meta is None:
        return (
            "This checkpoint carries no front-end artefact: it was trained on data without one and consumes the "
            "cached feature columns (`observation.vision_features`, `observation.language_features`) only. It "
            "cannot act from camera images and instructions directly.",
            "0",
        )
    language, vision = meta["language"], meta["vision"]
    cams = vision["cameras"]
    pca_values = language["n_components"] * language["input_dim"] + language["input_dim"] + sum(
        c["n_components"] * c["input_dim"] + c["input_dim"] for c in cams.values()
    )
    fit = meta.get("fit", {})
    lines = [
        "The frozen front end turns camera images and the instruction into the features the policy predicts. It is "
        f"published with the weights (`{FRONTEND_DIR}/` when present, and inside the preprocessor's "
        "`predvla_frontend_processor` step), so `lerobot-eval` recomputes exactly the training features.",
        "",
        "| part | value |",
        "|---|---|",
        f"| image encoder | {vision['encoder']}, weights: {vision.get('weights_description', vision['weights'])} |",
        f"| image weights SHA-256 | `{vision['fingerprint_sha256']}` |",
        f"| image precision | {vision['precision']} |",
        f"| cameras | {', '.join(f'`{k}`' for k in cams)} |",
        f"| image PCA | {', '.join(f'{c['input_dim']} -> {c['n_components']}' for c in cams.values())} per camera |",
        f"| language encoder | {language['encoder']} (from {language['source']}) |",
        f"| language PCA | {language['input_dim']} -> {language['n_components']} "
        f"({language['components_with_variance']} components with variance) |",
        f"| fitted on | {_format_fit(fit)} |",
    ]
    return "\n".join(lines), f"{pca_values:,}"


def _format_fit(fit: dict) -> str:
    if not fit:
        return "not recorded"
    # The fit records of `predvla fit-frontend` on LIBERO hdf5 (suites) or on a LeRobot dataset (dataset).
    keys = {"suites": "suites", "dataset": "dataset", "num_demos": "demonstrations", "num_frames": "frames",
            "num_distinct_instructions": "instructions"}
    parts = [f"{name}: {', '.join(map(str, v)) if isinstance(v, list) else v}"
             for k, name in keys.items() if (v := fit.get(k))]
    return "; ".join(parts) or "not recorded"


def _training_section(dataset: DatasetSummary | None, train_cfg: dict | None, config: dict,
                      records: list[dict] | None) -> str:
    lines = []
    if dataset is not None:
        tasks = "; ".join(dataset.tasks[:12]) + ("; ..." if len(dataset.tasks) > 12 else "")
        lines += [
            "| | |",
            "|---|---|",
            f"| dataset | `{dataset.repo_id}` |",
            f"| episodes | {dataset.episodes:,} |",
            f"| frames | {dataset.frames:,} ({dataset.fps} fps) |",
            f"| tasks | {len(dataset.tasks)}: {tasks} |",
        ]
    elif train_cfg is not None:
        lines.append(f"Dataset `{train_cfg['dataset']['repo_id']}` (not published with this checkpoint; the front "
                     "end's fit above counts its demonstrations).")
    else:
        lines.append("The training dataset was not recorded with this checkpoint.")
    trained = [r for r in records or [] if (r.get("commands") or {}).get("train")]
    if train_cfg is not None:
        steps = trained[0]["steps"] if trained else train_cfg["steps"]
        processes = training_processes(trained[0]["commands"]["train"]) if trained else 1
        batch = f"batch size {train_cfg['batch_size']}" + (
            f" per process, {processes} processes ({train_cfg['batch_size'] * processes} per step)"
            if processes > 1 else "")
        planned = f" (its training configuration planned {train_cfg['steps']:,})" if steps != train_cfg["steps"] else ""
        lines += ["", f"Trained for {steps:,} steps{planned}, {batch}, seed {train_cfg['seed']}."]
    from lerobot_predvla.experiments.headline import config_departures

    departures = config_departures(config)
    if departures:
        lines += ["", "Departures from the configuration class's defaults (for PredVLA: the paper's Table 2): "
                  + "; ".join(departures) + "."]
    return "\n".join(lines)


def inference_settings(record: dict, config: dict) -> dict:
    """The policy fields a recorded evaluation ran with that differ from the published `config.json`: the recorded
    training's `--policy.*` values (the checkpoint it evaluated) under the evaluation's overrides. A field that
    `config.json` lacks (saved before the field existed) loads as its default, so it is compared with that."""
    from lerobot_predvla.experiments.headline import config_defaults, differs
    from lerobot_predvla.experiments.sweep import NOT_RECIPE

    train = (record.get("commands") or {}).get("train") or []
    fields = dict(w[len("--policy."):].split("=", 1) for w in train if w.startswith("--policy.") and "=" in w)
    fields.update(record.get("eval_overrides") or {})
    loaded = {**config_defaults(config["type"]), **config} if "type" in config else config
    return {k: v for k, v in fields.items() if k in loaded and k not in NOT_RECIPE and differs(v, loaded[k])}


def _records_section(records: list[dict], config: dict) -> str:
    """Every evaluation of the checkpoint, from its run records (per-task successes from its eval_info.json)."""
    lines = [
        "Every evaluation of this checkpoint with `lerobot-eval --env.type=predvla_libero`, from the run records of "
        "`predvla sweep` (successes per task from each run's `eval_info.json`; inference: the policy fields the run "
        "used where they differ from `config.json`):",
        "",
        "| configuration | inference | starts | episodes per task | step cap | successes per task | total |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in sorted(records, key=lambda r: (r["results"], r["config"])):
        inference = ", ".join(f"`{k}={v}`" for k, v in inference_settings(r, config).items()) or "as in config.json"
        starts = ("official init states" if r.get("init_states", True) is not False
                  else f"randomised resets (seed {r.get('eval_seed')})")
        tasks = ", ".join(str(t["successes"]) for _, t in sorted(r["tasks"].items(), key=lambda kv: int(kv[0])))
        lines.append(f"| `{r['results']}` `{r['config']}` | {inference} | {starts} | {r['n_episodes_per_task']} | "
                     f"{r['episode_length']} | {tasks} | {r['successes']}/{r['episodes']} "
                     f"({100 * r['successes'] / r['episodes']:.1f}%) |")
    return "\n".join(lines)


def _results_section(report: Path | None, config_name: str | None, records: list[dict] | None = None,
                     config: dict | None = None) -> str:
    if records:
        return _records_section(records, config or {})
    if report is None:
        return "No evaluation results were attached when publishing (`predvla push --results REPORT_DIR`)."
    summary = load_summary(report)
    names = list(summary["configs"])
    name = config_name or ("predvla" if "predvla" in names else names[0] if len(names) == 1 else None)
    if name not in summary["configs"]:
        raise HubError(f"{report}: choose the configuration with --results-config; the report has {names}.")
    entry = summary["configs"][name]
    lines = [
        f"Success rate (%) on LIBERO, configuration `{name}`, mean +/- standard deviation across seeds "
        f"(from `predvla report`; {summary['protocol']}).",
        "",
        "| suite | success (%) | seeds |",
        "|---|---|---|",
    ]
    for suite, cell in entry["suites"].items():
        value = (f"{cell['mean']:.2f} +/- {cell['std']:.2f}" if cell["n"] > 1
                 else f"{cell['mean']:.2f}" if cell["n"] else "not run")
        lines.append(f"| {suite} | {value} | {cell['n']} |")
    for key, label in (("mean3", "3-suite mean"), ("mean4", "4-suite mean")):
        if entry.get(key) is not None:
            lines.append(f"| {label} | {entry[key]:.2f} | |")
    return "\n".join(lines)


def _policy_type(config: dict, where: Path) -> str:
    """The checkpoint's policy type, which must be one of this plugin's (else one clear line)."""
    policy_type = config.get("type")
    if policy_type not in POLICY_TYPES:
        raise HubError(
            f"{where}: policy type {policy_type!r} is not one of this plugin's ({', '.join(POLICY_TYPES)}); "
            "publish it with LeRobot's own push_to_hub."
        )
    return policy_type


def _model_section(config: dict) -> dict[str, str]:
    """Title, description and the type-specific lines of the card, for each policy type of the plugin."""
    policy_type = config["type"]
    config_cls = PreTrainedConfig.get_choice_class(policy_type)
    values = {
        "policy_type": policy_type,
        "policy_class": config_cls.__name__.removesuffix("Config") + "Policy",
        "posterior_note": "",
        "er_limitation": "",
    }
    shared = (
        "It reads the cached features of PredVLA's frozen front end and decodes a Gaussian-mixture action with "
        "PredVLA's head, trained on the same data."
    )
    if policy_type == "predvla":
        values["model_title"] = "PredVLA"
        values["model_description"] = (
            "PredVLA is a language-conditioned **predictive-coding** policy for robot manipulation (paper: *PredVLA: "
            "Predictive Sensorimotor Modeling for Sub-Million-Parameter Robot Manipulation*). A hierarchical recurrent "
            "network of four modules (task T, vision V, upper and lower action A) with time constants "
            f"{_format_value(config['tau'])} predicts visual features and proprioception and outputs a "
            "Gaussian-mixture action. Observations never enter the network as inputs: at every control step, *error "
            f"regression* adjusts the latent posteriors of the last {config['er_window']} steps by "
            f"{config['er_iterations']} Adam iterations (step {_format_value(config['er_lr'])}) to minimise the free "
            "energy of the prediction errors, and the action is decoded from the corrected state. Language "
            "conditions the top module."
        )
        values["posterior_note"] = (
            "Training posteriors (one latent per demonstration, step and module) are optimised during training only "
            "and are not part of this repository."
        )
        values["er_limitation"] = (
            f"- Error regression runs {config['er_iterations']} optimiser iterations per control step; its cost "
            f"grows with the window ({config['er_window']} steps).\n"
        )
    elif policy_type == "predvla_ladder":
        values["model_title"] = f"PredVLA ladder rung {config['rung']}"
        values["model_description"] = (
            f"Rung {config['rung']} of the paper's mechanism ladder from PredVLA to BC-RNN (Section 4.5): PredVLA with "
            "part of its mechanism removed (no free variables or error regression from L2 on; observations as "
            f"inputs from L3; no temporal hierarchy from L4; LSTM cells at L5). {shared}"
        )
    elif policy_type == "predvla_bc_rnn":
        values["model_title"] = "BC-RNN baseline"
        values["model_description"] = (
            "The paper's BC-RNN baseline (B2): an LSTM over held visual features, proprioception and the instruction "
            f"embedding, trained by behaviour cloning. {shared}"
        )
    else:
        values["model_title"] = f"BC-Transformer baseline (chunk {config['chunk_size']})"
        values["model_description"] = (
            "The paper's BC-Transformer baseline (B1, B3, B4 by action chunk size): a causal Transformer over a window "
            f"of held visual features, proprioception and the instruction embedding, trained by behaviour cloning. "
            f"{shared}"
        )
    return values


def render_card(
    files: dict[str, Path | bytes],
    repo_id: str,
    dataset: DatasetSummary | None = None,
    report: Path | None = None,
    report_config: str | None = None,
    records: list[dict] | None = None,
    baselines: list[dict] | None = None,
) -> str:
    """The model card for the files about to be published, with every value filled in. `repo_id` is where a reader
    loads it from (a Hub repo, or a directory of this repository); `records`: its evaluations (`evaluation_records`),
    shown instead of a report's aggregate, and `baselines` the BC runs beside them (`baseline_records`)."""
    config = read_json(files, "config.json")
    train_cfg = read_json(files, "train_config.json") if "train_config.json" in files else None
    dataset_repo_id = dataset.repo_id if dataset else (train_cfg["dataset"]["repo_id"] if train_cfg else "unknown")
    frontend_section, pca_values = _frontend_section(frontend_metadata(files))
    _policy_type(config, files["config.json"])
    model = _model_section(config)
    lerobot_fields = {f.name for f in dataclasses.fields(PreTrainedConfig)}
    config_cls = PreTrainedConfig.get_choice_class(config["type"])
    own_fields = [f.name for f in dataclasses.fields(config_cls) if f.name not in lerobot_fields]
    features = {**config.get("input_features", {}), **config.get("output_features", {})}
    is_predictive = config["type"] == "predvla" or config.get("rung") in PREDICTIVE_RUNGS
    main = main_record(records or [], config)
    protocol = (main["episode_length"], main["n_episodes_per_task"]) if main else ()
    values = {
        "license": config.get("license") or "apache-2.0",
        "dataset_repo_id": dataset_repo_id,
        "tags_yaml": "\n".join(f"- {tag}" for tag in (*TAGS, *([PREDICTIVE_TAG] * is_predictive))),
        "repo_id": repo_id,
        **model,
        "lerobot_version": package_version("lerobot"),
        "plugin_version": package_version("lerobot_policy_predvla"),
        "trainable_params": f"{count_parameters(files['model.safetensors']):,}",
        "resnet_params": f"{RESNET18_BACKBONE_PARAMS:,}",
        "minilm_params": f"{MINILM_PARAMS:,}",
        "pca_values": pca_values,
        "io_rows": "\n".join(
            f"| `{key}` | {tuple(ft['shape'])} | {feature_meaning(key, ft)} |"
            for key, ft in features.items()
        ),
        "frontend_section": frontend_section,
        "training_section": _training_section(dataset, train_cfg, config, records),
        "config_rows": "\n".join(
            f"| `{k}` | {_format_value(config[k])}{PAPER_ONLY_NOTE if k in PAPER_ONLY_FIELDS else ''} |"
            for k in own_fields if k in config),
        "eval_command": eval_command(repo_id, _suite_of(dataset_repo_id) or "libero_object", *protocol),
        "eval_protocol": eval_protocol(main),
        "results_section": _results_section(report, report_config, records, config),
        "result_limitations": result_limitations(records or [], baselines or [], config),
        "seed_limitation": (f"This checkpoint is one training seed ({train_cfg['seed']}); " if train_cfg else "")
        + "success rates vary substantially between training seeds of the same recipe: compare recipes over several "
        "seeds.",
        "extra_limitations": "" if _suite_of(dataset_repo_id) else (
            f"- The training dataset `{dataset_repo_id}` is not a LIBERO suite: the evaluation command above is "
            "only the protocol's form."
        ),
    }
    if not CARD_TEMPLATE.is_file():
        raise HubError(f"{CARD_TEMPLATE}: model card template missing (reinstall lerobot_policy_predvla).")
    card = Template(CARD_TEMPLATE.read_text()).substitute(values)
    leftover = _LEFTOVER.findall(card)
    if leftover:
        raise HubError(f"{CARD_TEMPLATE}: placeholders left after rendering: {sorted(set(leftover))}.")
    return card


# ----- checkpoints committed in this repository ----------------------------------------------------------
def shipped_checkpoints(root: Path) -> list[Path]:
    """The checkpoint directories committed under `root/checkpoints/`: every folder holding a policy `config.json`,
    both `checkpoints/<name>/` and the models sweeps publish (`train.publish`, e.g.
    `checkpoints/<sweep>/<config>_seed<seed>/`)."""
    return sorted(config.parent for config in (Path(root) / "checkpoints").rglob("config.json"))


def repository_files(checkpoint: Path, root: Path) -> dict[str, bytes]:
    """The configs and model card of a checkpoint directory committed in this repository (`root`), as every publishing
    route writes them: configs without the training machine's paths and device (`without_machine_paths`), the card
    loaded from the checkpoint's path with every evaluation recorded under `root/results/`. `predvla report --docs`
    writes them into the checkpoint (its weights are never rewritten)."""
    checkpoint, root = Path(checkpoint).resolve(), Path(root).resolve()
    files = without_machine_paths(publishable_files(checkpoint))
    records = evaluation_records(checkpoint, root / "results")
    card = render_card(files, checkpoint.relative_to(root).as_posix(), records=records,
                       baselines=baseline_records(records, root / "results"))
    return {**{rel: src for rel, src in files.items() if isinstance(src, bytes)}, CARD_FILE: card.encode()}


# ----- upload ----------------------------------------------------------------------------------------------
def upload_files(
    files: dict[str, Path | bytes], repo_id: str, private: bool | None, commit_message: str, token: str | None = None
) -> str:
    """Create the model repository if needed and commit `files` to it; returns the commit URL."""
    api = HfApi(token=token)
    repo_id = api.create_repo(repo_id=repo_id, repo_type="model", private=private, exist_ok=True).repo_id
    operations = [
        CommitOperationAdd(path_in_repo=rel, path_or_fileobj=src if isinstance(src, bytes) else str(src))
        for rel, src in sorted(files.items())
    ]
    info = api.create_commit(repo_id=repo_id, repo_type="model", operations=operations, commit_message=commit_message)
    return info.commit_url


def collect_checkpoint(checkpoint: Path, frontend: Path | None = None) -> tuple[dict[str, Path], Path | None]:
    """Files to publish from a saved checkpoint, and the training dataset root recorded in it (if any)."""
    pretrained = pretrained_dir(checkpoint)
    files = publishable_files(pretrained)
    dataset_root = None
    if "train_config.json" in files:
        root = json.loads(files["train_config.json"].read_text())["dataset"].get("root")
        dataset_root = Path(root) if root else None
    source = frontend_source(pretrained, dataset_root, frontend)
    if source is not None:
        files = {k: v for k, v in files.items() if not k.startswith(f"{FRONTEND_DIR}/")}
        files.update({f"{FRONTEND_DIR}/{name}": source / name for name in (METADATA_FILE, TENSORS_FILE)})
    return files, dataset_root


def push_checkpoint(
    checkpoint: Path,
    repo_id: str,
    *,
    private: bool | None = None,
    frontend: Path | None = None,
    report: Path | None = None,
    report_config: str | None = None,
    dry_run: bool = False,
) -> tuple[dict[str, Path | bytes], str | None]:
    """Publish a saved checkpoint with its card in one commit. Returns the files and the commit URL.

    `report`: a `predvla report` output (its aggregate for `report_config`), or a results folder such as this
    repository's `results/`, whose sweep run records of this checkpoint fill the card's results (`evaluation_records`).
    """
    files, dataset_root = collect_checkpoint(checkpoint, frontend)
    records = baselines = None
    if report is not None and Path(report).is_dir() and not (Path(report) / SUMMARY_FILE).is_file():
        records = evaluation_records(pretrained_dir(checkpoint), report)
        baselines = baseline_records(records, report)
        if not records:
            raise HubError(f"{report}: neither a report ({SUMMARY_FILE}) nor a results folder with run records "
                           f"(*/runs/records/) of {checkpoint}.")
        report = None
    _policy_type(json.loads(files["config.json"].read_text()), files["config.json"])
    dataset = None
    if dataset_root is not None and "train_config.json" in files:
        repo = json.loads(files["train_config.json"].read_text())["dataset"]["repo_id"]
        dataset = DatasetSummary.from_root(repo, dataset_root)
    published = without_machine_paths(files)
    published[CARD_FILE] = render_card(published, repo_id, dataset, report, report_config, records,
                                       baselines).encode()
    published[MANIFEST_FILE] = manifest_text(published).encode()  # SHA-256 of every file of the commit
    if dry_run:
        return published, None
    return published, upload_files(published, repo_id, private, "Upload PredVLA policy, processors, front end, card")


def push_policy(
    policy, repo_id: str, *, cfg=None, state_dict=None, dataset_meta=None, private: bool | None = None
) -> str:
    """Publish an in-memory policy: the network (no posteriors), train config when given, artefact and card.

    `lerobot-train --policy.push_to_hub=true` reaches this through `PredVLAPolicy.push_model_to_hub` (with the
    train config and dataset metadata), `policy.push_to_hub(repo_id)` without them.
    """
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp)
        policy.save_pretrained(stage, state_dict=state_dict)
        if cfg is not None:
            cfg.save_pretrained(stage)
        root = Path(dataset_meta.root) if dataset_meta is not None else None
        source = frontend_source(stage, root, None)
        if source is not None and source != stage / FRONTEND_DIR:
            shutil.copytree(source, stage / FRONTEND_DIR, ignore=shutil.ignore_patterns(".*"))
        published = without_machine_paths(publishable_files(stage))
        dataset = DatasetSummary.from_meta(dataset_meta) if dataset_meta is not None else None
        published[CARD_FILE] = render_card(published, repo_id, dataset).encode()
        published[MANIFEST_FILE] = manifest_text(published).encode()
        return upload_files(published, repo_id, private, "Upload PredVLA policy weights, train config, front end, card")
