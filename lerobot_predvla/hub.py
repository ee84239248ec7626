"""Publishing PredVLA checkpoints on the Hugging Face Hub with the model card of `hub_cards/predvla.md`.

Two routes end in `upload_files` (one `HfApi.create_commit`):
- `lerobot-train ... --policy.push_to_hub=true --policy.repo_id=...`: `PredVLAPolicy.push_model_to_hub` calls
  `push_trained_policy` at the end of training (LeRobot then pushes the processors in their own commits);
- `predvla push CHECKPOINT_DIR REPO_ID`: `push_checkpoint` publishes a saved checkpoint in one commit.

What is published: `config.json`, `model.safetensors`, `train_config.json`, the processors
(`policy_preprocessor*.json/.safetensors`, `policy_postprocessor*`, which carry the front-end artefact), the
artefact itself as `predvla_frontend/` when available, and `README.md` (the card). Never the training
posteriors (`posterior_store.safetensors`) nor `training_state/` (optimizer, scheduler, RNG).
"""

import dataclasses
import importlib.metadata
import json
import re
import shutil
import sys
import tempfile
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path
from string import Template

from huggingface_hub import CommitOperationAdd, HfApi
from lerobot.configs import PreTrainedConfig
from safetensors import safe_open

from .configuration_predvla import PredVLAConfig
from .frontend.artefact import FRONTEND_META_DIR, METADATA_FILE, TENSORS_FILE
from .posterior_store import POSTERIOR_STORE_FILE
from .sweep import EVAL_ENV_TYPE, PAPER_EPISODE_LENGTH, PAPER_EPISODES_PER_TASK, SUITES

# The source checkout's hub_cards/, or the copy a wheel installs under <prefix>/share (pyproject data-files).
CARD_TEMPLATE = next(
    (p for p in (Path(__file__).resolve().parent.parent / "hub_cards" / "predvla.md",
                 Path(sys.prefix) / "share" / "lerobot_predvla" / "hub_cards" / "predvla.md") if p.is_file()),
    Path(__file__).resolve().parent.parent / "hub_cards" / "predvla.md",
)
CARD_FILE = "README.md"
FRONTEND_DIR = "predvla_frontend"  # the artefact's folder inside a checkpoint and a Hub repo
PUSH_PATTERNS = ("*.safetensors", "*.json", "*.yaml", "*.md")  # what LeRobot's own push uploads
NEVER_PUSHED = (POSTERIOR_STORE_FILE,)
REQUIRED_FILES = ("config.json", "model.safetensors")
TAGS = ("robotics", "lerobot", "predvla", "predictive-coding", "libero")
# Frozen encoders (counted once: torchvision resnet18 without `fc`; sentence-transformers all-MiniLM-L6-v2).
RESNET18_BACKBONE_PARAMS = 11_176_512
MINILM_PARAMS = 22_713_216
FRONTEND_STEP = "predvla_frontend_processor"
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
    checkpoint = Path(checkpoint)
    for candidate in (checkpoint, checkpoint / "pretrained_model"):
        if all((candidate / name).is_file() for name in REQUIRED_FILES):
            return candidate
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


def frontend_metadata(files: dict[str, Path]) -> dict | None:
    """The artefact's `frontend.json`, from the published folder or from the preprocessor's front-end step."""
    if f"{FRONTEND_DIR}/{METADATA_FILE}" in files:
        return json.loads(files[f"{FRONTEND_DIR}/{METADATA_FILE}"].read_text())
    if "policy_preprocessor.json" in files:
        for step in json.loads(files["policy_preprocessor.json"].read_text()).get("steps", []):
            if step.get("registry_name") == FRONTEND_STEP and step.get("config", {}).get("artefact"):
                return step["config"]["artefact"]
    return None


def count_parameters(weights: Path) -> int:
    """Number of values in a safetensors file (read from its header)."""
    total = 0
    with safe_open(str(weights), framework="pt") as f:
        for key in f.keys():
            n = 1
            for dim in f.get_slice(key).get_shape():
                n *= dim
            total += n
    return total


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


def _version(distribution: str) -> str:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return "(not installed)"


def _format_value(value) -> str:
    if isinstance(value, list | tuple):
        return "(" + ", ".join(_format_value(v) for v in value) + ")"
    if isinstance(value, float):
        return f"{value:g}"
    return f"`{value}`" if isinstance(value, str) else str(value)


def _suite_of(dataset_repo_id: str) -> str | None:
    return next((s for s in sorted(SUITES, key=len, reverse=True) if s in dataset_repo_id), None)


def eval_command(repo_id: str, suite: str) -> str:
    return (
        f"lerobot-eval --policy.path={repo_id} --env.type={EVAL_ENV_TYPE} --env.task={suite} "
        f"--env.episode_length={PAPER_EPISODE_LENGTH} --eval.n_episodes={PAPER_EPISODES_PER_TASK} "
        "--eval.batch_size=1 --eval.use_async_envs=false --policy.device=cuda --output_dir=outputs/eval"
    )


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


def _training_section(dataset: DatasetSummary | None, train_cfg: dict | None) -> str:
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
        lines.append(f"Dataset `{train_cfg['dataset']['repo_id']}` (its metadata was not available when publishing).")
    else:
        lines.append("The training dataset was not recorded with this checkpoint.")
    if train_cfg is not None:
        lines += [
            "",
            f"Trained for {train_cfg['steps']:,} steps, batch size {train_cfg['batch_size']}, "
            f"seed {train_cfg['seed']}.",
        ]
    return "\n".join(lines)


def _results_section(report: Path | None, config_name: str | None) -> str:
    if report is None:
        return "No evaluation results were attached when publishing (`predvla push --results REPORT_DIR`)."
    from .report import load_summary  # the JSON that `predvla report` writes

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
        value = f"{cell['mean']:.2f} +/- {cell['std']:.2f}" if cell["n"] else "not run"
        lines.append(f"| {suite} | {value} | {cell['n']} |")
    for key, label in (("mean3", "3-suite mean"), ("mean4", "4-suite mean")):
        if entry.get(key) is not None:
            lines.append(f"| {label} | {entry[key]:.2f} | |")
    return "\n".join(lines)


def render_card(
    files: dict[str, Path],
    repo_id: str,
    dataset: DatasetSummary | None = None,
    report: Path | None = None,
    report_config: str | None = None,
) -> str:
    """The model card for the files about to be published, with every value filled in."""
    config = json.loads(files["config.json"].read_text())
    train_cfg = json.loads(files["train_config.json"].read_text()) if "train_config.json" in files else None
    dataset_repo_id = dataset.repo_id if dataset else (train_cfg["dataset"]["repo_id"] if train_cfg else "unknown")
    frontend_section, pca_values = _frontend_section(frontend_metadata(files))
    own_fields = [f.name for f in dataclasses.fields(PredVLAConfig) if f.name not in {
        g.name for g in dataclasses.fields(PreTrainedConfig)}]
    features = {**config.get("input_features", {}), **config.get("output_features", {})}
    values = {
        "license": config.get("license") or "apache-2.0",
        "dataset_repo_id": dataset_repo_id,
        "tags_yaml": "\n".join(f"- {tag}" for tag in TAGS),
        "repo_id": repo_id,
        "tau": _format_value(config["tau"]),
        "er_window": str(config["er_window"]),
        "er_iterations": str(config["er_iterations"]),
        "er_lr": _format_value(config["er_lr"]),
        "lerobot_version": _version("lerobot"),
        "plugin_version": _version("lerobot_policy_predvla"),
        "trainable_params": f"{count_parameters(files['model.safetensors']):,}",
        "resnet_params": f"{RESNET18_BACKBONE_PARAMS:,}",
        "minilm_params": f"{MINILM_PARAMS:,}",
        "pca_values": pca_values,
        "io_rows": "\n".join(
            f"| `{key}` | {tuple(ft['shape'])} | {feature_meaning(key, ft)} |"
            for key, ft in features.items()
        ),
        "frontend_section": frontend_section,
        "training_section": _training_section(dataset, train_cfg),
        "config_rows": "\n".join(f"| `{k}` | {_format_value(config[k])} |" for k in own_fields if k in config),
        "eval_command": eval_command(repo_id, _suite_of(dataset_repo_id) or "libero_object"),
        "episodes_per_task": str(PAPER_EPISODES_PER_TASK),
        "episode_length": str(PAPER_EPISODE_LENGTH),
        "results_section": _results_section(report, report_config),
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
    """Publish a saved checkpoint with its card in one commit. Returns the files and the commit URL."""
    files, dataset_root = collect_checkpoint(checkpoint, frontend)
    dataset = None
    if dataset_root is not None and "train_config.json" in files:
        repo = json.loads(files["train_config.json"].read_text())["dataset"]["repo_id"]
        dataset = DatasetSummary.from_root(repo, dataset_root)
    card = render_card(files, repo_id, dataset, report, report_config)
    published: dict[str, Path | bytes] = {**files, CARD_FILE: card.encode()}
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
        files = publishable_files(stage)
        dataset = DatasetSummary.from_meta(dataset_meta) if dataset_meta is not None else None
        published = {**files, CARD_FILE: render_card(files, repo_id, dataset).encode()}
        return upload_files(published, repo_id, private, "Upload PredVLA policy weights, train config, front end, card")
