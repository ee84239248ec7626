"""Faults and bad input at acting and training time (docs/reliability.md): no non-finite value ever reaches an
action, a weight, a posterior or a checkpoint."""

import ast
import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.datasets import LeRobotDatasetMetadata
from lerobot.policies.factory import make_policy
from safetensors.numpy import load_file as load_numpy
from safetensors.numpy import save_file as save_numpy
from safetensors.torch import load_file, save_file
from test_frontend import frontend_dir, libero_root  # noqa: F401  (module fixtures)
from test_policy import randomised_policy, run, stream

from lerobot_predvla import (
    PredVLABCRNNConfig,
    PredVLABCRNNPolicy,
    PredVLABCTransformerConfig,
    PredVLABCTransformerPolicy,
    PredVLAConfig,
    PredVLALadderConfig,
    PredVLALadderPolicy,
    PredVLAPolicy,
)
from lerobot_predvla.frontend.artefact import METADATA_FILE, TENSORS_FILE, FrontendArtefact, FrontendArtefactError
from lerobot_predvla.policies.common.observation_guard import FALLBACK, BadObservationError
from lerobot_predvla.policies.common.training_guard import NonFiniteTrainingError
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE
from lerobot_predvla.utils.safe_loading import CheckpointError, read_safetensors

VISION, STATE, LANGUAGE = "observation.vision_features", "observation.state", "observation.language_features"


def spoil(observations: list[dict], step: int, key: str, env: int | None, value: float = float("nan")) -> list[dict]:
    """A copy of the stream with one environment's row (or, env=None, the whole key) spoiled at one step."""
    out = [dict(o) for o in observations]
    if env is None:
        del out[step][key]
    else:
        x = out[step][key].clone()
        x[env, 3] = value
        out[step][key] = x
    return out


def assert_window_finite(policy) -> None:
    er = policy.error_regression
    assert all(torch.isfinite(c).all() for c in er.posteriors)
    state = er.state
    assert all(torch.isfinite(x).all() for x in (*state.h, *state.d, state.a_hat, state.q_hat))


@pytest.mark.parametrize(("key", "value"), [(VISION, float("nan")), (STATE, float("inf")), (STATE, float("-inf")),
                                            (VISION, float("inf"))])
def test_a_bad_value_never_reaches_actions_posteriors_or_state(key, value):
    policy = randomised_policy(er_iterations=3, er_window=6)
    clean = stream(14)
    actions = run(policy, spoil(clean, 4, key, 0, value))  # step 4 is a visual refresh
    assert torch.isfinite(actions).all()
    assert_window_finite(policy)
    assert policy.guard.counts[key].tolist() == [1] and policy.guard.totals[FALLBACK] == 0
    reference = run(policy, clean)
    assert torch.equal(actions[:4], reference[:4])
    assert not torch.equal(actions[4:], reference[4:])  # masked, not ignored: inference differs from then on


def test_masking_equals_a_missing_observation():
    """A non-finite row is treated exactly as a missing key: its error leaves the free energy."""
    policy = randomised_policy(er_iterations=3, er_window=6)
    clean = stream(10)
    for key in (VISION, STATE):
        assert torch.equal(run(policy, spoil(clean, 4, key, 0)), run(policy, spoil(clean, 4, key, None)))


def test_a_bad_frame_between_refreshes_changes_nothing():
    """Vision of a non-refresh step never enters the free energy, so even NaN there changes no bit."""
    policy = randomised_policy(er_iterations=3, er_window=6)
    clean = stream(10)
    assert torch.equal(run(policy, spoil(clean, 5, VISION, 0)), run(policy, clean))


def test_one_environments_bad_frames_change_nothing_for_the_others():
    policy = randomised_policy(er_iterations=3, er_window=6)
    clean = stream(16, batch=3, seed=7)
    bad = spoil(spoil(spoil(clean, 4, VISION, 1), 6, STATE, 1), 9, STATE, 1, float("inf"))
    actions = run(policy, bad)
    assert policy.guard.counts[VISION].tolist() == [0, 1, 0] and policy.guard.counts[STATE].tolist() == [0, 2, 0]
    reference = run(policy, clean)
    assert torch.isfinite(actions).all()
    assert torch.equal(actions[:, [0, 2]], reference[:, [0, 2]])  # bit for bit
    assert not torch.equal(actions[:, 1], reference[:, 1])


def test_counts_are_reported_once_per_episode(caplog):
    policy = randomised_policy(er_iterations=1, er_window=4)
    with caplog.at_level(logging.WARNING):
        run(policy, spoil(spoil(stream(8, batch=2), 0, VISION, 1), 2, STATE, None))
        run(policy, stream(3, batch=2))  # the reset at its start reports the previous episode
        run(policy, stream(3, batch=2))  # a clean episode reports nothing
    lines = [r.getMessage() for r in caplog.records if "unavailable" in r.getMessage()]
    assert len(lines) == 1, lines
    assert f"{VISION} unavailable (masked) at 1 env-steps (per env [0, 1])" in lines[0]
    assert f"{STATE} unavailable (masked) at 2 env-steps (per env [1, 1])" in lines[0]
    assert policy.guard.totals[VISION] == 1 and policy.guard.totals[STATE] == 2


def test_raise_mode_stops_with_a_clear_error():
    policy = randomised_policy(er_iterations=1, er_window=4, on_bad_observation="raise")
    with pytest.raises(BadObservationError, match=rf"'{STATE}' of environment 1 is non-finite at control step 3"):
        run(policy, spoil(stream(6, batch=2), 3, STATE, 1))
    with pytest.raises(BadObservationError, match=rf"'{VISION}' of environment 0 is missing at control step 2"):
        run(policy, spoil(stream(6, batch=2), 2, VISION, None))
    with pytest.raises(ValueError, match="on_bad_observation"):
        randomised_policy(on_bad_observation="ignore")


def test_diverging_inference_reverts_to_the_prior():
    """Should error regression itself diverge (here an infinite step size), posteriors revert to their values
    before the update and the action stays finite."""
    policy = randomised_policy(er_iterations=2, er_window=4, er_lr=float("inf"))
    actions = run(policy, stream(6, batch=2))
    assert torch.isfinite(actions).all()
    assert_window_finite(policy)
    assert policy.error_regression.reverted == 12
    open_loop = run(randomised_policy(er_iterations=0), stream(6, batch=2))
    torch.testing.assert_close(actions, open_loop, rtol=1e-5, atol=1e-5)


def test_a_nonfinite_action_falls_back_to_the_open_loop_action(monkeypatch):
    policy = randomised_policy(er_iterations=1, er_window=4)
    policy.reset()
    real_act = type(policy.error_regression).act

    def act_with_nan(er):
        action = real_act(er).clone()
        action[1] = float("nan")
        return action

    monkeypatch.setattr(type(policy.error_regression), "act", act_with_nan)
    with torch.inference_mode():
        action = policy.select_action(stream(1, batch=2)[0])
    assert torch.isfinite(action).all()
    assert torch.equal(action[1], policy.error_regression.prior_action[1])
    assert policy.guard.totals[FALLBACK] == 1


BASELINES = {
    "B1 (bc_rnn)": lambda **kw: PredVLABCRNNPolicy(PredVLABCRNNConfig(device="cpu", **kw)),
    "B3 (bc_transformer)": lambda **kw: PredVLABCTransformerPolicy(PredVLABCTransformerConfig(
        device="cpu", chunk_size=4, embed_dim=32, num_layers=1, feedforward_dim=64, context_length=6,
        head_hidden_dim=32, **kw)),
    "L3": lambda **kw: PredVLALadderPolicy(PredVLALadderConfig(device="cpu", rung="L3", **kw)),
    "L5": lambda **kw: PredVLALadderPolicy(PredVLALadderConfig(device="cpu", rung="L5", **kw)),
}


@pytest.mark.parametrize("name", list(BASELINES))
def test_baselines_hold_their_last_available_input(name):
    torch.manual_seed(0)
    policy = BASELINES[name]().eval()
    clean = stream(10, batch=3, seed=2)
    one_env = spoil(spoil(clean, 4, VISION, 1), 5, STATE, 1, float("inf"))
    assert torch.equal(run(policy, one_env)[:, [0, 2]], run(policy, clean)[:, [0, 2]])  # bit for bit
    bad = spoil(one_env, 7, STATE, None)
    actions = run(policy, bad)
    assert torch.isfinite(actions).all()
    # The held input equals feeding the last available value explicitly.
    held = [dict(o) for o in clean]
    held[4][VISION] = held[4][VISION].clone()
    held[4][VISION][1] = held[0][VISION][1]  # the refresh at step 4 keeps step 0's frame
    held[5][STATE] = held[5][STATE].clone()
    held[5][STATE][1] = held[4][STATE][1]
    held[7][STATE] = held[6][STATE]
    torch.testing.assert_close(actions, run(policy, held), rtol=0, atol=0)
    with pytest.raises(BadObservationError):
        run(BASELINES[name](on_bad_observation="raise").eval(), bad)


# ----- training -------------------------------------------------------------------------------------------------
def built_for_training(synthetic_dataset, **overrides) -> PredVLAPolicy:
    meta = LeRobotDatasetMetadata("local/predvla_synthetic", root=synthetic_dataset)
    config = PredVLAConfig(device="cpu", sequence_length=32, **overrides)
    return make_policy(config, ds_meta=meta).train()


def train_step(policy, episodes: list[int]) -> None:
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=1e-3)
    loss, _ = policy.forward({"episode_index": torch.tensor(episodes)})
    loss.backward()
    torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
    optimizer.step()
    policy.update()
    optimizer.zero_grad()


def snapshot(policy) -> dict[str, torch.Tensor]:
    """Weights, training posteriors, their Adam moments and step counts."""
    store = policy.posterior_store.state() if policy.posterior_store is not None else {}
    store = {f"posterior_store.{k}": v.clone() for k, v in store.items()}
    return {**{n: p.detach().clone() for n, p in policy.named_parameters()}, **store}


def unchanged(before: dict[str, torch.Tensor], after: dict[str, torch.Tensor]) -> bool:
    """Every tensor bit for bit the same (NaN equal to NaN)."""
    return all(torch.allclose(before[n], after[n], rtol=0, atol=0, equal_nan=True) for n in before)


def test_a_nonfinite_loss_stops_training_with_one_line(synthetic_dataset):
    policy = built_for_training(synthetic_dataset)
    train_step(policy, [0, 2])
    with torch.no_grad():
        policy.posterior_store.latents[3, 5, 7] = float("nan")
    before = snapshot(policy)
    with pytest.raises(NonFiniteTrainingError) as stop:
        train_step(policy, [1, 3])
    message = str(stop.value)
    assert "\n" not in message and "non-finite loss at training step 2" in message
    assert "vision_error=nan" in message and "action_nll=" in message and "complexity=" in message
    assert unchanged(before, snapshot(policy))


def test_a_nonfinite_gradient_stops_training_before_the_optimizer(synthetic_dataset):
    policy = built_for_training(synthetic_dataset)
    policy.model.bias[0].register_hook(lambda g: g * float("inf"))
    before = snapshot(policy)
    with pytest.raises(NonFiniteTrainingError, match=r"non-finite gradient of model\.bias\.0 at training step 1"):
        train_step(policy, [0, 1])
    assert unchanged(before, snapshot(policy))


@pytest.mark.parametrize("fault", ["loss", "gradient"])
def test_skip_leaves_every_weight_and_posterior_untouched(synthetic_dataset, fault, caplog):
    policy = built_for_training(synthetic_dataset, on_nonfinite_training="skip")
    if fault == "loss":
        with torch.no_grad():
            policy.posterior_store.latents[1, 0, 0] = float("inf")
    else:
        handle = policy.model.bias[0].register_hook(lambda g: g * float("nan"))
    before = snapshot(policy)
    with caplog.at_level(logging.WARNING):
        train_step(policy, [1, 2])
    after = snapshot(policy)
    assert unchanged(before, after)
    assert all(p.grad is None for p in policy.parameters())
    assert policy.posterior_store.steps.sum() == 0  # no posterior row was stepped either
    assert policy.training_guard.skipped == 1
    assert any(f"non-finite {fault}" in r.getMessage() and "batch skipped (1 so far)" in r.getMessage()
               for r in caplog.records)
    if fault == "gradient":
        handle.remove()
    train_step(policy, [0, 2])  # a good batch trains again
    assert not torch.equal(snapshot(policy)["model.bias.0"], after["model.bias.0"])


def run_lerobot_train(dataset, out, *extra: str) -> subprocess.CompletedProcess:
    cmd = [str(Path(sys.executable).with_name("lerobot-train")), "--policy.type=predvla",
           "--dataset.repo_id=local/predvla_synthetic", f"--dataset.root={dataset}", "--policy.push_to_hub=false",
           "--policy.device=cpu", "--num_workers=0", "--steps=6", "--save_freq=1", "--log_freq=1", "--batch_size=2",
           "--wandb.enable=false", "--policy.sequence_length=32", f"--output_dir={out}", "--seed=3",
           "--policy.optimizer_lr=1e30", "--policy.posterior_lr=1e30", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})


def checkpoints_are_finite(out: Path) -> list[Path]:
    files = sorted(out.glob("checkpoints/0*/pretrained_model/*.safetensors"))  # not the `last` link
    for file in files:
        for key, tensor in load_file(str(file)).items():
            assert torch.isfinite(tensor).all(), (file, key)
    return files


@pytest.mark.slow
def test_lerobot_train_stops_on_divergence_before_a_nonfinite_checkpoint(synthetic_dataset, tmp_path):
    """A learning rate of 1e30 makes the loss non-finite within a few steps of the real lerobot-train."""
    result = run_lerobot_train(synthetic_dataset, tmp_path / "run")
    assert result.returncode == 1, result.stderr[-3000:]
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("predvla: non-finite") and "at training step" in last and "action_nll=" in last, last
    step = int(last.split("at training step ")[1].split()[0])
    assert 1 < step <= 6
    files = checkpoints_are_finite(tmp_path / "run")
    assert len({f.parent.parent.name for f in files}) == step - 1  # every completed step was saved, finite


@pytest.mark.slow
def test_lerobot_train_skips_nonfinite_batches_when_asked(synthetic_dataset, tmp_path):
    result = run_lerobot_train(synthetic_dataset, tmp_path / "run", "--policy.on_nonfinite_training=skip")
    assert result.returncode == 0, result.stderr[-3000:]
    assert "batch skipped" in result.stderr
    files = checkpoints_are_finite(tmp_path / "run")
    assert {f.parent.parent.name for f in files} == {f"{s:06d}" for s in range(1, 7)}


# ----- loading ----------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def saved(synthetic_dataset, tmp_path_factory) -> tuple[Path, PredVLAPolicy]:
    """A training checkpoint: model.safetensors and posterior_store.safetensors."""
    policy = built_for_training(synthetic_dataset)
    train_step(policy, [0, 1])
    out = tmp_path_factory.mktemp("ckpt")
    policy.save_pretrained(out)
    return out, policy


def tampered(saved_dir: Path, tmp_path: Path, file: str, mutate) -> Path:
    out = tmp_path / "ckpt"
    shutil.copytree(saved_dir, out)
    if mutate in FILE_DAMAGE:
        mutate(out / file)
    else:  # edits the tensors
        tensors, metadata = read_safetensors(out / file)
        mutate(tensors)
        save_file(tensors, str(out / file), metadata=metadata)
    return out


def _nan_weight(t: dict) -> None:
    t["model.prior.1.weight"][3, 4] = float("nan")


def _half_precision(t: dict) -> None:
    t["model.v_head.0.bias"] = t["model.v_head.0.bias"].half()


def _drop_key(t: dict) -> None:
    del t["model.lang.weight"]


def _reshape(t: dict) -> None:
    t["model.prior.0.weight"] = t["model.prior.0.weight"][:32].clone()


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _garbage(path: Path) -> None:
    path.write_bytes(b"\x00not safetensors" * 64)


FILE_DAMAGE = (_truncate, _garbage)
BAD_WEIGHTS = {
    "truncated": (_truncate, ["truncated or corrupt"]),
    "garbage": (_garbage, ["truncated or corrupt"]),
    "nan weight": (_nan_weight, ["key 'model.prior.1.weight'", "non-finite value nan at index [3, 4]"]),
    "other dtype": (_half_precision, ["'model.v_head.0.bias' is (256,) torch.float16", "needs (256,) torch.float32"]),
    "missing key": (_drop_key, ["another model or config", "missing keys ['model.lang.weight']"]),
    "other config": (_reshape, ["'model.prior.0.weight' is (32, 64)", "needs (64, 64)"]),
}


@pytest.mark.parametrize("case", list(BAD_WEIGHTS))
def test_a_bad_weights_file_fails_with_one_line_and_loads_nothing(saved, tmp_path, case):
    mutate, fragments = BAD_WEIGHTS[case]
    ckpt = tampered(saved[0], tmp_path, "model.safetensors", mutate)
    with pytest.raises(CheckpointError if case != "nan weight" else ValueError) as err:
        PredVLAPolicy.from_pretrained(ckpt)
    message = str(err.value)
    assert "\n" not in message and str(ckpt / "model.safetensors") in message
    for fragment in fragments:
        assert fragment in message, message
    target = randomised_policy()
    before = snapshot(target)
    with pytest.raises(ValueError):
        PredVLAPolicy._load_as_safetensor(target, str(ckpt / "model.safetensors"), "cpu", True)
    assert unchanged(before, snapshot(target))


BAD_POSTERIORS = {
    "truncated": (_truncate, ["truncated or corrupt"]),
    "nan posterior": (lambda t: t["latents"].__setitem__((2, 3, 4), float("inf")),
                      ["key 'latents'", "non-finite value inf at index [2, 3, 4]"]),
    "other dataset": (lambda t: t.__setitem__("latents", t["latents"][:5].clone()),
                      ["'latents' is (5, 32, 256)", "needs (8, 32, 256)", "another config or dataset"]),
}


@pytest.mark.parametrize("case", list(BAD_POSTERIORS))
def test_a_bad_posterior_store_fails_before_the_weights_load(saved, synthetic_dataset, tmp_path, case):
    mutate, fragments = BAD_POSTERIORS[case]
    ckpt = tampered(saved[0], tmp_path, POSTERIOR_STORE_FILE, mutate)
    target = built_for_training(synthetic_dataset)  # as lerobot-train --resume builds it
    before = snapshot(target)
    with pytest.raises(ValueError) as err:
        PredVLAPolicy._load_as_safetensor(target, str(ckpt / "model.safetensors"), "cpu", True)
    message = str(err.value)
    assert "\n" not in message and str(ckpt / POSTERIOR_STORE_FILE) in message
    for fragment in fragments:
        assert fragment in message, message
    assert unchanged(before, snapshot(target))  # neither the network nor the posteriors
    PredVLAPolicy._load_as_safetensor(target, str(saved[0] / "model.safetensors"), "cpu", True)
    assert unchanged(snapshot(saved[1]), snapshot(target))


def test_a_baseline_checkpoint_is_checked_the_same_way(tmp_path):
    torch.manual_seed(0)
    policy = BASELINES["B1 (bc_rnn)"]()
    policy.save_pretrained(tmp_path / "b1")
    _truncate(tmp_path / "b1" / "model.safetensors")
    with pytest.raises(CheckpointError, match="truncated or corrupt"):
        PredVLABCRNNPolicy.from_pretrained(tmp_path / "b1")


BAD_ARTEFACTS = {
    "truncated arrays": (TENSORS_FILE, _truncate, ["unreadable front-end artefact"]),
    "nan component": (TENSORS_FILE, lambda p: _edit_arrays(p, "vision/observation.images.image/components", np.nan),
                      ["key 'vision/observation.images.image/components'", "non-finite value nan at index [0, 1]"]),
    "other shape": (TENSORS_FILE, lambda p: _edit_arrays(p, "language/mean", None),
                    ["tensor 'language/mean' has shape (383,)", "says (384,)"]),
    "malformed json": (METADATA_FILE, lambda p: p.write_text(json.dumps(
        {k: v for k, v in json.loads(p.read_text()).items() if k != "vision"})), ["malformed frontend.json", "vision"]),
}


def _edit_arrays(path: Path, key: str, value: float | None) -> None:
    arrays = load_numpy(str(path))
    if value is None:
        arrays[key] = arrays[key][:-1].copy()
    else:
        arrays[key][0, 1] = value
    save_numpy(arrays, str(path))


@pytest.mark.parametrize("case", list(BAD_ARTEFACTS))
def test_a_bad_front_end_artefact_fails_with_one_line(frontend_dir, tmp_path, case):  # noqa: F811
    file, mutate, fragments = BAD_ARTEFACTS[case]
    artefact_dir = tmp_path / "fe"
    shutil.copytree(frontend_dir, artefact_dir)
    mutate(artefact_dir / file)
    with pytest.raises(FrontendArtefactError) as err:
        FrontendArtefact.load(artefact_dir)
    message = str(err.value)
    assert "\n" not in message and str(artefact_dir) in message
    for fragment in fragments:
        assert fragment in message, message


def test_loading_never_unpickles():
    """Every torch.load in the package passes weights_only=True; nothing imports pickle or allows it in numpy."""
    package = Path(__file__).resolve().parents[1] / "lerobot_predvla"
    for path in package.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom):
                names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
                assert not any(n and n.split(".")[0] in ("pickle", "dill", "joblib") for n in names), path
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "load":
                owner = ast.unparse(node.func.value)
                keywords = {k.arg: ast.unparse(k.value) for k in node.keywords}
                if owner == "torch":
                    assert keywords.get("weights_only") == "True", f"{path}:{node.lineno}"
                if owner in ("np", "numpy"):
                    assert keywords.get("allow_pickle", "False") == "False", f"{path}:{node.lineno}"
