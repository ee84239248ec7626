"""The model card of a published policy (`hub/predvla_card.md` filled in): what the policy is, its inputs and
outputs, front end, training data, configuration, evaluation command and results.

Each policy type of the plugin supplies its own section (`MODEL_SECTIONS`); a type without one is an error. The results
come from the checkpoint's evaluation records (`evaluation_records`: the run records of `predvla sweep`) or from a
`predvla report` table (`report_results`). Nothing here uploads (hub/upload.py does).
"""

import dataclasses
import importlib.resources
import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from string import Template

from lerobot.configs import PreTrainedConfig
from lerobot.utils.constants import POLICY_PREPROCESSOR_DEFAULT_NAME

from lerobot_predvla.columns import SUITES
from lerobot_predvla.frontend.artefact import METADATA_FILE
from lerobot_predvla.lerobot_commands import eval_command as lerobot_eval
from lerobot_predvla.policies import POLICY_TYPES
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PREDICTIVE_RUNGS
from lerobot_predvla.policies.recipe import NOT_RECIPE, config_defaults, config_departures, differs
from lerobot_predvla.sims.libero.protocol import (
    EVAL_ENV_TYPE,
    PAPER_EPISODE_LENGTH,
    PAPER_EPISODES_PER_TASK,
    PAPER_OBJECT,
)
from lerobot_predvla.utils.checkpoints import TRAIN_DONE_FILE
from lerobot_predvla.utils.manifest import sha256_file
from lerobot_predvla.utils.parameters import count_parameters
from lerobot_predvla.utils.versions import package_version

# Package data of lerobot_predvla.hub (pyproject package-data), read with importlib.resources.
CARD_TEMPLATE = importlib.resources.files("lerobot_predvla.hub") / "predvla_card.md"
CARD_FILE = "README.md"
FRONTEND_DIR = "predvla_frontend"  # the artefact's folder inside a checkpoint and a Hub repo
TAGS = ("robotics", "lerobot", "predvla", "libero")
PREDICTIVE_TAG = "predictive-coding"  # PredVLA and the ladder rungs that keep its predictive network
# Frozen encoders (counted once: torchvision resnet18 without `fc`; sentence-transformers all-MiniLM-L6-v2).
RESNET18_BACKBONE_PARAMS = 11_176_512
MINILM_PARAMS = 22_713_216
FRONTEND_STEP = "predvla_frontend_processor"
PREPROCESSOR_FILE = f"{POLICY_PREPROCESSOR_DEFAULT_NAME}.json"
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



def read_json(files: dict[str, Path | bytes], name: str) -> dict:
    """A JSON file about to be published, from its path or from the bytes that replace it."""
    source = files[name]
    return json.loads(source if isinstance(source, bytes) else source.read_text())




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
    return " ".join(lerobot_eval(program="lerobot-eval", checkpoint=policy_path, env_type=EVAL_ENV_TYPE, suite=suite,
                                 episode_length=episode_length, n_episodes=episodes_per_task, batch_size=1,
                                 output_dir="outputs/eval"))


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
    """Whether a record's episodes start from the official init states as LIBERO sets them: not randomised resets,
    and no object shifted, no LIBERO-PRO / LIBERO-plus variant, no corrupted observation."""
    return record.get("init_states", True) is not False and not any(
        record.get(key) for key in ("object_shift", "variant", "corruption"))


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


def training_command(checkpoint: Path, results_root: Path) -> list[str] | None:
    """The `lerobot-train` command of the `predvla sweep` training that published `checkpoint`, from its training
    record (`runs/train/<config>/<suite>/seed<k>/predvla_sweep_train.json` under `results_root`), or None."""
    checkpoint = Path(checkpoint).resolve()
    for path in sorted(Path(results_root).glob(f"**/runs/train/*/*/seed*/{TRAIN_DONE_FILE}")):
        record = json.loads(path.read_text())
        if record.get("checkpoint") and (path.parents[4] / record["checkpoint"]).resolve() == checkpoint:
            return record.get("command")
    return None


def evaluation_records(checkpoint: Path, results_root: Path) -> list[dict]:
    """The `predvla sweep` run records under `results_root/*/runs/records/` that evaluated `checkpoint`: those whose
    `checkpoint` is this directory, those whose training (job name, dataset, seed and, where its command names it,
    step count) is the one its `train_config.json` records (a checkpoint copied out of a sweep's runs directory; a
    longer training of the same job is another model), and those that evaluated its
    weights (`model_sha256`: a published copy, e.g. `predvla push --out`, of a resumed training)."""
    checkpoint = Path(checkpoint).resolve()
    train_cfg_path = checkpoint / "train_config.json"
    train_cfg = json.loads(train_cfg_path.read_text()) if train_cfg_path.is_file() else {}
    weights = checkpoint / "model.safetensors"
    weights_sha256 = sha256_file(weights) if weights.is_file() else None
    found = []
    for path in sorted(Path(results_root).glob("**/runs/records/*/*/seed*.json")):
        record = json.loads(path.read_text())
        runs_dir = path.parents[3]
        recorded = record.get("checkpoint")
        train = (record.get("commands") or {}).get("train") or []
        same_dir = recorded is not None and (runs_dir / recorded).resolve() == checkpoint
        same_training = bool(train_cfg) and (
            _flag(train, "--job_name") == train_cfg.get("job_name")
            and _flag(train, "--dataset.repo_id") == train_cfg.get("dataset", {}).get("repo_id")
            and int(record["seed"]) == train_cfg.get("seed")
            and _flag(train, "--steps") in (None, str(train_cfg.get("steps"))))
        same_weights = weights_sha256 is not None and record.get("model_sha256") == weights_sha256
        if same_dir or same_training or same_weights:
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
                      records: list[dict] | None, train_command: list[str] | None = None) -> str:
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
        command = trained[0]["commands"]["train"] if trained else train_command
        processes = training_processes(command) if command else 1
        batch = f"batch size {train_cfg['batch_size']}" + (
            f" per process, {processes} processes ({train_cfg['batch_size'] * processes} per step)"
            if processes > 1 else "")
        planned = f" (its training configuration planned {train_cfg['steps']:,})" if steps != train_cfg["steps"] else ""
        lines += ["", f"Trained for {steps:,} steps{planned}, {batch}, seed {train_cfg['seed']}."]
    departures = config_departures(config)
    if departures:
        lines += ["", "Departures from the configuration class's defaults (for PredVLA: the paper's Table 2): "
                  + "; ".join(map(str, departures)) + "."]
    return "\n".join(lines)


def inference_settings(record: dict, config: dict) -> dict:
    """The policy fields a recorded evaluation ran with that differ from the published `config.json`: the recorded
    training's `--policy.*` values (the checkpoint it evaluated) under the evaluation's overrides. A field that
    `config.json` lacks (saved before the field existed) loads as its default, so it is compared with that."""
    train = (record.get("commands") or {}).get("train") or []
    fields = dict(w[len("--policy."):].split("=", 1) for w in train if w.startswith("--policy.") and "=" in w)
    fields.update(record.get("eval_overrides") or {})
    loaded = {**config_defaults(config["type"]), **config} if "type" in config else config
    return {k: v for k, v in fields.items() if k in loaded and k not in NOT_RECIPE and differs(v, loaded[k])}


def evaluation_starts(record: dict) -> str:
    """Where a run record's episodes started: official init states or randomised resets, with the object shift,
    the LIBERO-PRO / LIBERO-plus variant and the placement spread (`--env.placement_spread_cm`, read from its
    recorded evaluation command) it ran with."""
    words = ["official init states" if record.get("init_states", True) is not False
             else f"randomised resets (seed {record.get('eval_seed')})"]
    if shift := record.get("object_shift"):
        pattern = f", {shift['pattern']}" if shift.get("pattern") else ""
        words.append(f"object to pick moved {float(shift['cm']):g} cm{pattern}")
    if variant := record.get("variant"):
        words.append(f"variant {variant}")
    spreads = {a.split("=", 1)[1] for command in (record.get("commands") or {}).get("eval") or []
               for a in command if a.startswith("--env.placement_spread_cm=")}
    words += [f"objects moved {spread} cm (std per axis)" for spread in sorted(spreads)]
    return ", ".join(words)


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
        starts = evaluation_starts(r)
        tasks = ", ".join(str(t["successes"]) for _, t in sorted(r["tasks"].items(), key=lambda kv: int(kv[0])))
        lines.append(f"| `{r['results']}` `{r['config']}` | {inference} | {starts} | {r['n_episodes_per_task']} | "
                     f"{r['episode_length']} | {tasks} | {r['successes']}/{r['episodes']} "
                     f"({100 * r['successes'] / r['episodes']:.1f}%) |")
    return "\n".join(lines)


def report_results(summary: dict, report: Path, config_name: str | None) -> str:
    """The card's results from a `predvla report` summary (`report.json` of `report`, loaded): one configuration's
    success per suite; `config_name` chooses it (default `predvla`, or the report's only one)."""
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


def _results_section(report: str | None, records: list[dict] | None, config: dict) -> str:
    if records:
        return _records_section(records, config)
    if report is None:
        return "No evaluation results were attached when publishing (`predvla push --results REPORT_DIR`)."
    return report


def check_policy_type(config: dict, where: Path) -> str:
    """The checkpoint's policy type, which must be one of this plugin's (else one clear line)."""
    policy_type = config.get("type")
    if policy_type not in POLICY_TYPES:
        raise HubError(
            f"{where}: policy type {policy_type!r} is not one of this plugin's ({', '.join(POLICY_TYPES)}); "
            "publish it with LeRobot's own push_to_hub."
        )
    return policy_type


_SHARED_HEAD = (
    "It reads the cached features of PredVLA's frozen front end and decodes a Gaussian-mixture action with "
    "PredVLA's head, trained on the same data."
)


def _predvla_section(config: dict) -> dict[str, str]:
    return {
        "model_title": "PredVLA",
        "model_description": (
            "PredVLA is a language-conditioned **predictive-coding** policy for robot manipulation (paper: *PredVLA: "
            "Predictive Sensorimotor Modeling for Sub-Million-Parameter Robot Manipulation*). A hierarchical recurrent "
            "network of four modules (task T, vision V, upper and lower action A) with time constants "
            f"{_format_value(config['tau'])} predicts visual features and proprioception and outputs a "
            "Gaussian-mixture action. Observations never enter the network as inputs: at every control step, *error "
            f"regression* adjusts the latent posteriors of the last {config['er_window']} steps by "
            f"{config['er_iterations']} Adam iterations (step {_format_value(config['er_lr'])}) to minimise the free "
            "energy of the prediction errors, and the action is decoded from the corrected state. Language "
            "conditions the top module."
        ),
        "posterior_note": (
            "Training posteriors (one latent per demonstration, step and module) are optimised during training only "
            "and are not part of this repository."
        ),
        "er_limitation": (
            f"- Error regression runs {config['er_iterations']} optimiser iterations per control step; its cost "
            f"grows with the window ({config['er_window']} steps).\n"
        ),
    }


def _ladder_section(config: dict) -> dict[str, str]:
    return {
        "model_title": f"PredVLA ladder rung {config['rung']}",
        "model_description": (
            f"Rung {config['rung']} of the paper's mechanism ladder from PredVLA to BC-RNN (Section 4.5): PredVLA with "
            "part of its mechanism removed (no free variables or error regression from L2 on; observations as "
            f"inputs from L3; no temporal hierarchy from L4; LSTM cells at L5). {_SHARED_HEAD}"
        ),
    }


def _bc_rnn_section(config: dict) -> dict[str, str]:
    return {
        "model_title": "BC-RNN baseline",
        "model_description": (
            "The paper's BC-RNN baseline (B2): an LSTM over held visual features, proprioception and the instruction "
            f"embedding, trained by behaviour cloning. {_SHARED_HEAD}"
        ),
    }


def _bc_transformer_section(config: dict) -> dict[str, str]:
    return {
        "model_title": f"BC-Transformer baseline (chunk {config['chunk_size']})",
        "model_description": (
            "The paper's BC-Transformer baseline (B1, B3, B4 by action chunk size): a causal Transformer over a window "
            f"of held visual features, proprioception and the instruction embedding, trained by behaviour cloning. "
            f"{_SHARED_HEAD}"
        ),
    }


# Each policy type's own part of the card: title, description and, optionally, posterior note and error-regression
# limitation. tests/test_hub.py checks that every type of POLICY_TYPES has one.
MODEL_SECTIONS: dict[str, Callable[[dict], dict[str, str]]] = {
    "predvla": _predvla_section,
    "predvla_bc_transformer": _bc_transformer_section,
    "predvla_bc_rnn": _bc_rnn_section,
    "predvla_ladder": _ladder_section,
}


def _model_section(config: dict) -> dict[str, str]:
    """The card's values that depend on the policy type: its class and its own section (`MODEL_SECTIONS`)."""
    policy_type = config["type"]
    section = MODEL_SECTIONS.get(policy_type)
    if section is None:
        raise HubError(f"policy type {policy_type!r} has no model card section (hub/card.py MODEL_SECTIONS).")
    config_cls = PreTrainedConfig.get_choice_class(policy_type)
    return {
        "policy_type": policy_type,
        "policy_class": config_cls.__name__.removesuffix("Config") + "Policy",
        "posterior_note": "",
        "er_limitation": "",
        **section(config),
    }


def render_card(
    files: dict[str, Path | bytes],
    repo_id: str,
    dataset: DatasetSummary | None = None,
    report: str | None = None,
    records: list[dict] | None = None,
    baselines: list[dict] | None = None,
    train_command: list[str] | None = None,
) -> str:
    """The model card for the files about to be published, with every value filled in. `repo_id` is where a reader
    loads it from (a Hub repo, or a directory of this repository); `report`: a `predvla report` table
    (`report_results`); `records`: its evaluations (`evaluation_records`), shown instead of a report's table, and
    `baselines` the BC runs beside them (`baseline_records`); `train_command`: its training's command when no record
    carries one (`training_command`: a model trained with `predvla sweep --train-only`, not evaluated yet)."""
    config = read_json(files, "config.json")
    train_cfg = read_json(files, "train_config.json") if "train_config.json" in files else None
    dataset_repo_id = dataset.repo_id if dataset else (train_cfg["dataset"]["repo_id"] if train_cfg else "unknown")
    frontend_section, pca_values = _frontend_section(frontend_metadata(files))
    check_policy_type(config, files["config.json"])
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
        "training_section": _training_section(dataset, train_cfg, config, records, train_command),
        "config_rows": "\n".join(
            f"| `{k}` | {_format_value(config[k])}{PAPER_ONLY_NOTE if k in PAPER_ONLY_FIELDS else ''} |"
            for k in own_fields if k in config),
        "eval_command": eval_command(repo_id, _suite_of(dataset_repo_id) or "libero_object", *protocol),
        "eval_protocol": eval_protocol(main),
        "results_section": _results_section(report, records, config),
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
