"""Baselines B1-B4, ladder L1-L5/L2b, ablations A1-A6 (Tables 4-6) and the error-regression corruption."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from lerobot.configs import PreTrainedConfig
from lerobot.datasets import LeRobotDatasetMetadata
from lerobot.policies.factory import get_policy_class, make_policy, make_pre_post_processors
from test_policy import observation

import lerobot_policy_predvla  # noqa: F401  (registers the policy types, as LeRobot's plugin loader does)
from lerobot_predvla import PredVLAConfig, PredVLAPolicy
from lerobot_predvla.policies.bc_transformer.modeling_predvla_bc_transformer import (
    PredVLABCTransformerConfig,
    PredVLABCTransformerPolicy,
)
from lerobot_predvla.policies.common.sequence_table import read_columns
from lerobot_predvla.policies.ladder.configuration_predvla_ladder import PredVLALadderConfig
from lerobot_predvla.policies.ladder.modeling_predvla_ladder import PredVLALadderPolicy
from lerobot_predvla.policies.predvla.corruption import replaced
from lerobot_predvla.utils.parameters import count_parameters

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "policy"
PREDVLA = 675_732
# Paper's trainable parameters (Tables 3-5) and whether our reading matches exactly. A2/A3 remove the bottleneck
# (2 x 256 x 32) and the efference maps ((7 + 9) x 256); the paper gives no count for them.
PAPER_PARAMETERS = {
    "predvla": (PREDVLA, True), "predvla_long": (PREDVLA, True),
    "B1": (646_628, False), "B2": (674_276, False), "B3": (772_558, False), "B4": (916_478, False),
    "L1": (PREDVLA, True), "L2": (PREDVLA, True), "L2b": (724_884, True), "L3": (674_560, True),
    "L4": (674_560, True), "L5": (676_928, True),
    "A1": (PREDVLA, True), "A2": (PREDVLA - 16_384, True), "A3": (PREDVLA - 4_096, True),
    "A4": (PREDVLA, True), "A5": (PREDVLA, True), "A6": (PREDVLA, True),
}


def preset(name: str, **overrides) -> PreTrainedConfig:
    """The policy config of configs/policy/<name>.json, as `lerobot-train --config_path` builds it."""
    fields = {**json.loads((CONFIGS / f"{name}.json").read_text())["policy"], **overrides}
    return PreTrainedConfig.get_choice_class(fields.pop("type"))(device="cpu", **fields)




def run(policy, observations: list[dict]) -> torch.Tensor:
    policy.reset()
    with torch.inference_mode():  # as lerobot-eval calls it
        return torch.stack([policy.select_action(o) for o in observations])


# Named recipes beside the paper's rows: the CPU recipes (docs/research/libero_object_cpu.md) and the reading of
# the full-scale dynamics run (docs/research/dynamics.md).
NAMED_RECIPES = {"predvla_cpu", "predvla_cpu_lambda_q100", "predvla_fit_sensory_olt"}


def test_every_table_row_has_a_config():
    assert sorted(p.stem for p in CONFIGS.glob("*.json") if p.stem not in NAMED_RECIPES) == sorted(PAPER_PARAMETERS)


def test_cpu_recipe_keeps_the_paper_architecture():
    """The CPU recipe changes optimisation only: same network, 675,732 parameters, Table 2's complexity weights."""
    config = preset("predvla_cpu")
    assert count_parameters(get_policy_class(config.type)(config)) == PAPER_PARAMETERS["predvla"][0]
    assert config.complexity_weights == (0.05, 0.02, 0.02, 0.01) and config.optimizer_lr == 1e-3
    assert config.open_loop_weight == 1.0 and PredVLAConfig().open_loop_weight == 0.0


def test_proprioceptive_recipe_departs_in_the_training_weight_only():
    """predvla_cpu_lambda_q100 is the CPU recipe with lambda_q = 100 in training (Eq. 10; Table 2: 1) and Table 2's
    er_lambda_q = 1 in error regression: every other field as predvla_cpu.json."""
    recipe, base = preset("predvla_cpu_lambda_q100"), preset("predvla_cpu")
    assert (recipe.lambda_q, recipe.er_lambda_q) == (100.0, 1.0) == (100.0, PredVLAConfig().er_lambda_q)
    assert PredVLAConfig().lambda_q == base.lambda_q == 1.0
    assert {**vars(recipe), "lambda_q": base.lambda_q} == vars(base)
    assert count_parameters(get_policy_class(recipe.type)(recipe)) == PAPER_PARAMETERS["predvla"][0]


def test_fit_sensory_olt_recipe_departs_in_the_two_reading_fields_only():
    """predvla_fit_sensory_olt is predvla.json (Table 2) with the training posteriors fitted without the action term
    and the open-loop term on: same network, same training protocol, every other field at the paper's value."""
    recipe, base = preset("predvla_fit_sensory_olt"), preset("predvla")
    assert (recipe.posteriors_fit_actions, recipe.open_loop_weight) == (False, 1.0)
    assert (base.posteriors_fit_actions, base.open_loop_weight) == (True, 0.0)
    assert {**vars(recipe), "posteriors_fit_actions": True, "open_loop_weight": 0.0} == vars(base)
    files = [json.loads((CONFIGS / f"{name}.json").read_text()) for name in ("predvla_fit_sensory_olt", "predvla")]
    assert [{k: v for k, v in f.items() if k != "policy"} for f in files] == [{"steps": 30_000, "batch_size": 32}] * 2
    assert count_parameters(get_policy_class(recipe.type)(recipe)) == PAPER_PARAMETERS["predvla"][0]


@pytest.mark.parametrize("name", sorted(PAPER_PARAMETERS))
def test_parameter_count_matches_the_paper(name):
    config = preset(name)
    policy = get_policy_class(config.type)(config)
    ours, (paper, exact) = count_parameters(policy), PAPER_PARAMETERS[name]
    if exact:
        assert ours == paper
    else:
        assert abs(ours - paper) / paper < 0.01, (ours, paper)


def test_paper_protocol_fields():
    assert preset("B1").train_steps == preset("B2").train_steps == 50_000
    assert json.loads((CONFIGS / "B4.json").read_text())["steps"] == 50_000
    assert json.loads((CONFIGS / "L3.json").read_text())["steps"] == 30_000
    assert preset("L4").tau == preset("L5").tau == (1.0,) * 4 and preset("L3").tau == (16, 8, 5, 2)
    assert preset("A1").tau == (7.75,) * 4 == (sum(PredVLAConfig().tau) / 4,) * 4
    assert preset("B3").chunk_size == 8 and preset("B4").chunk_size == 16
    assert preset("B1", optimizer_lr=3e-4).get_optimizer_preset().lr == 3e-4  # the four-point sweep is a loop
    assert preset("predvla_long").sequence_length == 500
    with pytest.raises(ValueError, match="rung"):
        PredVLALadderConfig(rung="L7")


@pytest.fixture(scope="module")
def meta(synthetic_dataset) -> LeRobotDatasetMetadata:
    return LeRobotDatasetMetadata("local/predvla_synthetic", root=synthetic_dataset)


@pytest.mark.parametrize("name", sorted(PAPER_PARAMETERS))
def test_one_training_step_and_select_action(name, meta):
    """Built like lerobot-train builds it; one optimiser step changes the weights; one action through the processors."""
    torch.manual_seed(0)
    config = preset(name, sequence_length=32, er_window=4, er_iterations=1) if name.startswith(("predvla", "A", "L1")) \
        else preset(name, sequence_length=32)
    policy = make_policy(config, ds_meta=meta)
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=1e-3)
    before = [p.detach().clone() for p in policy.parameters()]
    loss, terms = policy.forward({"episode_index": torch.tensor([0, 5])})
    assert torch.isfinite(loss) and "action_nll" in terms
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    assert any(not torch.equal(a, b) for a, b in zip(before, policy.parameters(), strict=True))
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=meta.stats)
    policy.eval().reset()
    with torch.inference_mode():
        action = postprocessor(policy.select_action(preprocessor(observation())))
    assert action.shape == (1, 7) and torch.isfinite(action).all()


def test_vision_is_held_between_refreshes():
    """Observation-driven policies see a frame only at refresh steps (every 4), as in training."""
    policy = PredVLALadderPolicy(PredVLALadderConfig(device="cpu", rung="L3")).eval()
    stream = [observation(2, seed=t) for t in range(9)]
    other = [{**o, "observation.vision_features": torch.randn(2, 192)} if t % 4 else o for t, o in enumerate(stream)]
    torch.testing.assert_close(run(policy, stream), run(policy, other), rtol=0, atol=0)
    refreshed = [{**o, "observation.vision_features": torch.randn(2, 192)} if t == 4 else o
                 for t, o in enumerate(stream)]
    assert not torch.allclose(run(policy, stream)[4:], run(policy, refreshed)[4:])


def test_l2_is_predvla_with_every_posterior_at_its_prior():
    """L2 acts like the same PredVLA network in exact open loop; L2b with W_vis = 0 is L2."""
    torch.manual_seed(0)
    l2b = PredVLALadderPolicy(PredVLALadderConfig(device="cpu", rung="L2b")).eval()
    with torch.no_grad():
        for p in l2b.model.parameters():
            if p.dim() == 1:
                p.normal_(0, 0.3)
    open_loop = PredVLAPolicy(PredVLAConfig(device="cpu", er_iterations=0)).eval()
    open_loop.model.load_state_dict(l2b.model.state_dict())
    stream = [observation(1, seed=t) | {"observation.language_features": observation(1)[
        "observation.language_features"]} for t in range(10)]
    assert not torch.allclose(run(l2b, stream), run(open_loop, stream))  # the visual input acts
    with torch.no_grad():
        l2b.visual_input.weight.zero_()
    torch.testing.assert_close(run(l2b, stream), run(open_loop, stream))


def test_chunked_transformer_uses_act_temporal_ensembling():
    torch.manual_seed(0)
    config = PredVLABCTransformerConfig(device="cpu", chunk_size=4, embed_dim=32, num_layers=1, feedforward_dim=64,
                                        context_length=6, head_hidden_dim=32)
    policy = PredVLABCTransformerPolicy(config).eval()
    stream = [observation(2, seed=t) for t in range(8)]
    policy.reset()
    with torch.inference_mode():
        chunks = [policy.predict_action_chunk(o) for o in stream]
    assert chunks[0].shape == (2, 4, 7)
    weights = torch.exp(-config.temporal_ensemble_coeff * torch.arange(4))
    actions = run(policy, stream)
    for t in range(len(stream)):  # step t averages chunk t-i's i-th action, oldest first with weight w_i
        preds = [chunks[t - i][:, i] for i in range(min(t, 3), -1, -1)]
        w = weights[: len(preds)]
        torch.testing.assert_close(actions[t], sum(wi * p for wi, p in zip(w, preds, strict=True)) / w.sum())


@pytest.mark.parametrize("alpha", [0.25, 0.5, 0.75, 1.0])
def test_corruption_schedule_replaces_exactly_alpha_of_every_window(alpha):
    for start in range(0, 50):
        assert sum(replaced(t, alpha) for t in range(start, start + 40)) == 40 * alpha


@pytest.mark.parametrize(("channel", "alpha"), [("proprio", 0.25), ("vision", 0.5)])
def test_corruption_reaches_error_regression_on_one_channel(channel, alpha, synthetic_dataset):
    """Exactly the scheduled steps of one channel come from the unrelated episode; the other is untouched."""
    policy = PredVLAPolicy(PredVLAConfig(
        device="cpu", module_dims=(8, 16, 16, 16), latent_dim=4, bottleneck_dim=4, head_hidden_dim=16,  # tiny
        er_window=40, er_iterations=1, er_corruption_channel=channel, er_corruption_alpha=alpha,
        er_corruption_root=str(synthetic_dataset), er_corruption_episode=3,
    )).eval()
    stream = [observation(2, seed=t) for t in range(14)]
    run(policy, stream)
    er = policy.error_regression
    key = {"vision": "observation.vision_features", "proprio": "observation.state"}[channel]
    other_key = "observation.state" if channel == "vision" else "observation.vision_features"
    columns = read_columns(synthetic_dataset, ["episode_index", key])
    source = torch.from_numpy(columns[key][columns["episode_index"][:, 0] == 3])
    seen = {"observation.vision_features": er.vision, "observation.state": er.proprio}
    expected_steps = [t for t in range(14) if replaced(t // (4 if channel == "vision" else 1), alpha)]
    assert expected_steps == ([3, 7, 11] if channel == "proprio" else [4, 5, 6, 7, 12, 13])
    for t, obs in enumerate(stream):
        want = source[t].expand(2, -1) if t in expected_steps else obs[key]
        torch.testing.assert_close(seen[key][t], want, rtol=0, atol=0)
        torch.testing.assert_close(seen[other_key][t], obs[other_key], rtol=0, atol=0)
    assert math.isclose(len(expected_steps) / 14, alpha, abs_tol=0.2)
    with pytest.raises(ValueError, match="er_corruption_root"):
        PredVLAConfig(er_corruption_channel="vision", er_corruption_alpha=0.5)


@pytest.mark.slow
def test_lerobot_train_cli_runs_a_baseline_config(synthetic_dataset, tmp_path):
    """`lerobot-train --config_path configs/policy/B2.json` finds the plugin's type and trains."""
    cmd = [
        str(Path(sys.executable).with_name("lerobot-train")), f"--config_path={CONFIGS / 'B2.json'}",
        "--dataset.repo_id=local/predvla_synthetic", f"--dataset.root={synthetic_dataset}", "--policy.device=cpu",
        "--num_workers=0", "--steps=2", "--batch_size=2", "--log_freq=1", "--wandb.enable=false",
        "--policy.sequence_length=32", f"--output_dir={tmp_path / 'run'}",
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-3000:]
    layout = "2 cameras x 96, state 9, action 7, language 64"
    assert f"predvla_bc_rnn: 675,595 trainable parameters ({layout}; paper: 674,276" in log and "action_nll" in log
    assert (tmp_path / "run" / "checkpoints" / "000002" / "pretrained_model" / "model.safetensors").is_file()
    # A saved BC-RNN checkpoint publishes with its own card (it used to fail on PredVLA's `tau`).
    push = subprocess.run(
        [str(Path(sys.executable).with_name("predvla")), "push", str(tmp_path / "run" / "checkpoints" / "last"),
         "someone/bc", "--dry-run"],
        capture_output=True, text=True, env={**os.environ, "HF_HUB_OFFLINE": "1"},
    )
    assert push.returncode == 0, push.stderr
    assert "README.md" in push.stdout and "train_config.json" in push.stdout
