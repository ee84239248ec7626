"""Publishing a policy on the Hugging Face Hub: which files of a saved policy go, cleared of the training machine's
paths, with its card (hub/card.py) and SHA-256 manifest, in one `HfApi.create_commit`.

Two routes end in `upload_files`:
- `lerobot-train ... --policy.push_to_hub=true --policy.repo_id=...`: `PredVLAPolicy.push_model_to_hub` calls
  `push_policy` at the end of training (LeRobot then pushes the processors in their own commits);
- `predvla push CHECKPOINT_DIR REPO_ID`: `push_checkpoint` publishes a saved checkpoint in one commit.

What is published: `config.json`, `model.safetensors`, `train_config.json`, the processors
(`policy_preprocessor*.json/.safetensors`, `policy_postprocessor*`, which carry the front-end artefact), the
artefact itself as `predvla_frontend/` when available, `README.md` (the card) and `sha256_manifest.json` (the
SHA-256 of every file of the commit, verified on loading). Never the training
posteriors (`posterior_store.safetensors`) nor `training_state/` (optimizer, scheduler, RNG).

The checkpoints committed to this repository (`shipped_checkpoints`) hold the same files: `stale_checkpoint_files`
lists where they differ, which `predvla report --docs` rewrites and `--check` refuses.
"""

import json
import shutil
import tempfile
from fnmatch import fnmatch
from pathlib import Path

from huggingface_hub import CommitOperationAdd, HfApi

from lerobot_predvla.columns import FRONTEND_META_DIR
from lerobot_predvla.frontend.artefact import METADATA_FILE, TENSORS_FILE
from lerobot_predvla.hub.card import (
    CARD_FILE,
    FRONTEND_DIR,
    FRONTEND_STEP,
    PREPROCESSOR_FILE,
    DatasetSummary,
    HubError,
    baseline_records,
    check_policy_type,
    evaluation_records,
    read_json,
    render_card,
    training_command,
)
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE
from lerobot_predvla.utils.checkpoints import REQUIRED_FILES, find_pretrained
from lerobot_predvla.utils.manifest import MANIFEST_FILE, listed_files, manifest_text

PUSH_PATTERNS = ("*.safetensors", "*.json", "*.yaml", "*.md")  # what LeRobot's own push uploads
# A saved folder's manifest lists that folder (posterior store included); each publishing route writes the manifest
# of what it publishes instead.
NEVER_PUSHED = (POSTERIOR_STORE_FILE, MANIFEST_FILE)
# Policy config fields that name the training machine's resources: `pretrained_path` is where the checkpoint was
# loaded from (LeRobot sets it on loading and on `--resume`).
MACHINE_FIELDS = ("frontend_dir", "device", "pretrained_path")


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



def without_machine_paths(files: dict[str, Path]) -> dict[str, Path | bytes]:
    """The files as every route publishes them: the training machine's paths and device cleared from the configs.

    `frontend_dir` (the artefact is published beside the weights and inside the preprocessor), `pretrained_path`, the
    dataset root, the output and checkpoint directories and the front end's fitting data (the folders of `fit` in the
    artefact, in `predvla_frontend/` and in the preprocessor) name places on the training machine only; loading
    ignores them once they are None. The device is the training machine's too. LeRobot keeps a stored device that is
    available and picks the best available one when it is None: `config.json`'s when loading the policy
    (`--policy.path`, `from_pretrained`), and `train_config.json`'s policy device when training from it
    (`lerobot-train --config_path=...`, `--resume`). Both are cleared. The processors keep theirs: a device step
    needs a device (None fails to load); `lerobot-eval`, `lerobot-rollout`, `lerobot-train` and LeRobot's policy
    server replace the preprocessor's with the policy's, and the postprocessor's `cpu` is where actions go (the
    environment or robot), not where the policy trained. The front-end step's `device` of older checkpoints is
    ignored when loading (the encoders follow the images) and dropped.
    """
    published: dict[str, Path | bytes] = dict(files)
    if "config.json" in files:
        config = read_json(files, "config.json")
        published["config.json"] = json.dumps(
            {**config, **{k: None for k in MACHINE_FIELDS if k in config}}, indent=4).encode()
    if "train_config.json" in files:
        train_cfg = read_json(files, "train_config.json")
        train_cfg["output_dir"] = train_cfg["checkpoint_path"] = None
        if isinstance(train_cfg.get("dataset"), dict):
            train_cfg["dataset"]["root"] = None
        if isinstance(train_cfg.get("policy"), dict):
            train_cfg["policy"].update({k: None for k in MACHINE_FIELDS if k in train_cfg["policy"]})
        published["train_config.json"] = json.dumps(train_cfg, indent=4).encode()
    if PREPROCESSOR_FILE in files:
        preprocessor = read_json(files, PREPROCESSOR_FILE)
        for step in preprocessor.get("steps", []):
            if step.get("registry_name") == FRONTEND_STEP:
                step_config = step.get("config", {})
                step_config.pop("device", None)
                without_fit_root(step_config.get("artefact"))
        published[PREPROCESSOR_FILE] = json.dumps(preprocessor, indent=2).encode()  # LeRobot's layout
    artefact_file = f"{FRONTEND_DIR}/{METADATA_FILE}"
    if artefact_file in files:
        artefact = read_json(files, artefact_file)
        without_fit_root(artefact)
        published[artefact_file] = (json.dumps(artefact, indent=2) + "\n").encode()  # `FrontendArtefact.save`'s
    return published


def without_fit_root(artefact: dict | None) -> None:
    """Clear, in place, the directories a front-end artefact's PCA bases were fitted on (its `fit.hdf5_root`, or
    `fit.hdf5_roots` and each `fit.by_suite.<suite>.hdf5_root`); the rest of `fit` (suites, demonstrations, frames)
    says what they were fitted on."""
    fit = artefact.get("fit") if isinstance(artefact, dict) else None
    if not isinstance(fit, dict):
        return
    for record in [fit, *(fit.get("by_suite") or {}).values()]:
        for key in ("hdf5_root", "hdf5_roots"):
            if isinstance(record, dict) and key in record:
                record[key] = None




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
                       baselines=baseline_records(records, root / "results"),
                       train_command=training_command(checkpoint, root / "results"))
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
    report: str | None = None,
    results: Path | None = None,
    dry_run: bool = False,
) -> tuple[dict[str, Path | bytes], str | None]:
    """Publish a saved checkpoint with its card in one commit. Returns the files and the commit URL.

    `report`: the card's results table from a `predvla report` output (`card.report_results`); `results`: a results
    folder such as this repository's `results/`, whose sweep run records of this checkpoint fill the card's results
    instead (`evaluation_records`).
    """
    files, dataset_root = collect_checkpoint(checkpoint, frontend)
    records = baselines = None
    if results is not None:
        records = evaluation_records(pretrained_dir(checkpoint), results)
        baselines = baseline_records(records, results)
        if not records:
            raise HubError(f"{results}: neither a report nor a results folder with run records "
                           f"(*/runs/records/) of {checkpoint}.")
    check_policy_type(json.loads(files["config.json"].read_text()), files["config.json"])
    dataset = None
    if dataset_root is not None and "train_config.json" in files:
        repo = json.loads(files["train_config.json"].read_text())["dataset"]["repo_id"]
        dataset = DatasetSummary.from_root(repo, dataset_root)
    published = without_machine_paths(files)
    published[CARD_FILE] = render_card(published, repo_id, dataset, report, records, baselines).encode()
    published[MANIFEST_FILE] = manifest_text(published).encode()  # SHA-256 of every file of the commit
    if dry_run:
        return published, None
    return published, upload_files(published, repo_id, private, "Upload PredVLA policy, processors, front end, card")


def policy_card(policy, repo_id: str, *, cfg=None, dataset_meta=None) -> str:
    """The card of an in-memory policy (`PredVLAPolicy.generate_model_card`), from its saved files."""
    with tempfile.TemporaryDirectory() as tmp:
        policy.save_pretrained(Path(tmp))
        if cfg is not None:
            cfg.save_pretrained(Path(tmp))
        dataset = DatasetSummary.from_meta(dataset_meta) if dataset_meta is not None else None
        return render_card(without_machine_paths(publishable_files(Path(tmp))), repo_id, dataset)


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


def stale_checkpoint_files(root: Path) -> dict[Path, bytes]:
    """The files of each shipped checkpoint (`shipped_checkpoints`) that differ from what every publishing route
    writes (`repository_files`: configs that do not pin the
    training machine, the model card rendered from the checkpoint's config, training record and evaluations), with
    their new content; and the checkpoint's SHA-256 manifest where it has one, recomputed over its files with those
    contents."""

    stale = {}
    for checkpoint in shipped_checkpoints(root):
        changed = {rel: data for rel, data in repository_files(checkpoint, root).items()
                   if not (checkpoint / rel).is_file() or (checkpoint / rel).read_bytes() != data}
        manifest = checkpoint / MANIFEST_FILE
        if changed and manifest.is_file():
            changed[MANIFEST_FILE] = manifest_text({**listed_files(checkpoint), **changed}).encode()
        stale.update({checkpoint / rel: data for rel, data in changed.items()})
    return stale
