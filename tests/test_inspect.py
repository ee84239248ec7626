"""`predvla inspect` on a real lerobot-train output: numbers that describe the checkpoint, and the figures."""

import json

import pytest
from test_lerobot_cli import train

from lerobot_predvla.cli import main

pytestmark = pytest.mark.slow  # trains with the real lerobot-train


@pytest.fixture(scope="module")
def trained(synthetic_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("inspect") / "run"
    train(synthetic_dataset, out, 4)
    return out


def test_inspect_reports_every_checkpoint_and_draws_the_figures(trained, tmp_path):
    out = tmp_path / "inspect"
    assert main(["inspect", str(trained), "--out", str(out)]) == 0
    report = json.loads((out / "inspect.json").read_text())
    history = report["history"]
    assert [h["step"] for h in history] == [2, 4]
    last = history[-1]
    assert len(last["tasks"]) == 2
    lang = last["language"]
    # Each task's open loop is compared with both tasks' mean demonstrations; own and nearest-other agree with it.
    for i, row in enumerate(lang["open_loop_vs_mean_demos"]):
        assert lang["open_loop_mse_own_task"][i] == row[i]
        assert lang["open_loop_mse_nearest_other_task"][i] == min(v for j, v in enumerate(row) if j != i)
    assert lang["language_swap_mse"][0][0] == 0.0 and lang["language_swap_mse"][0][1] > 0.0
    # Each task's demonstrations spread around their mean (the synthetic episodes differ): a positive, finite floor.
    assert len(lang["demo_spread_mse"]) == 2 and all(0.0 < s < 1e3 for s in lang["demo_spread_mse"])
    assert set(last["posteriors"]) == {"T", "V", "A_top", "A_bottom"}
    assert all(p["mean_norm"] > 0 for p in last["posteriors"].values())  # 4 steps of Adam moved them
    er = last["error_regression"]
    assert er["er_action_mse"] >= 0 and er["open_loop_action_mse"] >= 0
    for timing in (er["er_gripper_timing"], er["open_loop_gripper_timing"]):
        assert set(timing) == {f"{e}{k}" for e in ("close", "release") for k in ("", "_abs", "_missing")}
    assert er["er_eps_v"] > 0 and er["er_eps_q"] > 0  # finite: the visual error of the refresh steps
    # Eq. 7's eps_q per proprioceptive dimension: open loop, from the training posteriors, and the demo floor.
    q = last["proprio_error_per_dim"]
    assert set(q) == {"open_loop", "posteriors", "demo_spread", "removed", "action_mse"}
    per_dim = [q[k] for k in ("open_loop", "posteriors", "demo_spread")]
    assert len({len(v) for v in per_dim}) == 1 and len(q["open_loop"]) > 1
    assert all(0.0 <= x < 1e3 for v in per_dim for x in v) and sum(q["demo_spread"]) > 0.0
    assert set(q["removed"]) == {"proprio", "vision", "action"} and all(x < 1.0 for x in q["removed"].values())
    assert q["removed"]["action"] == pytest.approx(1 - q["action_mse"]["posteriors"] / q["action_mse"]["open_loop"])
    assert set(last["forces"]["posterior_term_grad_norm"]) == {"T", "V", "A_top", "A_bottom"}
    for name in ("open_loop_vs_demos", "language_swap", "prior_posterior_gap", "errors_over_episode",
                 "training_curves", "proprio_error_per_dim"):
        assert (out / f"{name}.png").stat().st_size > 1000


def test_proprio_report_averages_to_the_models_eps_q(trained, synthetic_dataset):
    """The per-dimension open-loop error, averaged over dimensions, is Eq. 7's eps_q of the same rollout."""
    import torch

    from lerobot_predvla.policies.predvla import diagnostics as dx
    from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy

    policy = PredVLAPolicy.from_pretrained(trained / "checkpoints" / "last" / "pretrained_model").eval()
    data = dx.TaskData.load(synthetic_dataset, policy)
    per_dim = dx.proprio_report(policy, data, None)
    assert set(per_dim) == {"open_loop", "demo_spread", "action_mse"}
    model, seq = policy.model, data.sequences
    batch = seq.batch(torch.arange(seq.state.shape[0]), torch.device("cpu"))
    with torch.no_grad():
        traj = model.rollout(model.initial_state(len(batch["language"])), model.language_term(batch["language"]),
                             steps=batch["valid"].shape[0])
        _, eps_q = model.prediction_errors(traj, batch["vision"], batch["state"])
    expected = float(eps_q[batch["valid"]].mean())
    assert sum(per_dim["open_loop"]) / len(per_dim["open_loop"]) == pytest.approx(expected, rel=1e-5)


def test_removed_fraction_compares_the_posteriors_rollout_with_open_loop(trained, synthetic_dataset):
    """1 - eps(posteriors) / eps(open loop), eps_v on refresh steps only, from the checkpoint's own store."""
    import torch

    from lerobot_predvla.policies.predvla import diagnostics as dx
    from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy

    path = trained / "checkpoints" / "last" / "pretrained_model"
    policy = PredVLAPolicy.from_pretrained(path).eval()
    data, store = dx.TaskData.load(synthetic_dataset, policy), dx.load_store(path)
    report = dx.proprio_report(policy, data, store)
    removed = report["removed"]
    model, seq = policy.model, data.sequences
    batch = seq.batch(torch.arange(seq.state.shape[0]), torch.device("cpu"))
    valid = batch["valid"]
    fresh = valid & (torch.arange(valid.shape[0])[:, None] % policy.config.visual_refresh_interval == 0)
    errors = []
    with torch.no_grad():
        lang = model.language_term(batch["language"])
        for c_q in (None, store.transpose(0, 1)):
            traj = model.rollout(model.initial_state(valid.shape[1]), lang, c_q, steps=valid.shape[0])
            eps_v, eps_q = model.prediction_errors(traj, batch["vision"], batch["state"])
            raw_error = data.raw(traj.a_hat)[valid] - data.raw(batch["action"])[valid]
            errors.append((float(eps_q[valid].mean()), float(eps_v[fresh].mean()), float(raw_error.pow(2).mean())))
    (ol_q, ol_v, ol_a), (post_q, post_v, post_a) = errors
    assert removed["proprio"] == pytest.approx(1 - post_q / ol_q, rel=1e-5)
    assert removed["vision"] == pytest.approx(1 - post_v / ol_v, rel=1e-5)
    # The decoded actions against the demonstrated ones in raw units, as error regression's action MSE is reported.
    assert report["action_mse"] == pytest.approx({"open_loop": ol_a, "posteriors": post_a}, rel=1e-5)
    assert removed["action"] == pytest.approx(1 - post_a / ol_a, rel=1e-5)


def test_every_keeps_multiples_and_the_last_checkpoint(tmp_path):
    from lerobot_predvla.cli.inspect import find_checkpoints

    for step in (1000, 2000, 3000, 4000, 5000, 6000, 7000):
        (tmp_path / "checkpoints" / f"{step:06d}" / "pretrained_model").mkdir(parents=True)
        (tmp_path / "checkpoints" / f"{step:06d}" / "pretrained_model" / "config.json").write_text("{}")
    assert [s for s, _ in find_checkpoints(tmp_path, every=2500)] == [5000, 7000]
    assert [s for s, _ in find_checkpoints(tmp_path, every=1000)] == [1000, 2000, 3000, 4000, 5000, 6000, 7000]
    with pytest.raises(ValueError, match="--every"):
        find_checkpoints(tmp_path, every=0)


def test_inspect_names_a_path_without_checkpoint(tmp_path, capsys):
    assert main(["inspect", str(tmp_path)]) == 2
    assert str(tmp_path) in capsys.readouterr().err


def test_er_variants_replay_other_inference_settings(trained, tmp_path, capsys):
    """Each --er-variant is replayed with its settings: a vanishing step size leaves the open-loop actions."""
    out = tmp_path / "inspect"
    assert main(["inspect", str(trained), "--out", str(out),
                 "--er-variant", "er_lr=1e-9", "--er-variant", "er_lambda_q=0,er_iterations=3"]) == 0
    last = json.loads((out / "inspect.json").read_text())["history"][-1]
    own, (tiny, a5) = last["error_regression"], last["error_regression_variants"]
    assert tiny["settings"] == {"er_lr": 1e-9} and a5["settings"] == {"er_lambda_q": 0.0, "er_iterations": 3}
    assert tiny["er_action_mse"] == pytest.approx(own["open_loop_action_mse"], rel=1e-4)
    assert tiny["er_gripper_mse"] == pytest.approx(own["open_loop_gripper_mse"], rel=1e-4)
    assert own["er_action_mse"] != pytest.approx(own["open_loop_action_mse"], rel=1e-4)  # Table 2's settings move
    assert a5["er_action_mse"] != own["er_action_mse"]
    # The gaps as multiples of the training posteriors': a vanishing step size leaves the posteriors on their priors.
    assert set(own["er_gap_over_training"]) == {"T", "V", "A_top", "A_bottom"}
    assert all(tiny["er_gap_over_training"][m] < own["er_gap_over_training"][m] for m in own["er_gap_over_training"])
    assert own["er_gap_over_training"]["T"] == pytest.approx(
        own["er_gap_per_module"]["T"] / last["posteriors"]["T"]["prior_gap"])
    printed = capsys.readouterr().out
    assert "er_lr=1e-09" in printed and "er_lambda_q=0.0,er_iterations=3" in printed and "exact open loop" in printed


@pytest.mark.parametrize("flags", [["--er-variant", "er_lr"], ["--er-variant", "tau=2"],
                                   ["--er-variant", "er_iterations=0"], ["--er-variant", "er_lr=fast"],
                                   ["--er-variant", "er_adam_state=kept"], ["--er-variant", "er_lr=0.1", "--no-er"]])
def test_inspect_refuses_a_bad_er_variant(tmp_path, capsys, flags):
    assert main(["inspect", str(tmp_path), *flags]) == 2
    assert "--er-variant" in capsys.readouterr().err


def test_forces_split_the_gradient_by_term_and_weigh_the_decay_against_the_clipped_loss(trained, synthetic_dataset):
    """Each Eq. 10 term's gradient reaches only the weights it depends on (the priors' maps only through C, the
    visual head only through eps_v); the terms add up to the loss gradient; decay_over_loss is wd |p| against the
    clipped loss gradient; Adam's momentum is read by parameter name from the checkpoint's optimizer state."""
    import torch

    from lerobot_predvla.policies.predvla import diagnostics as dx
    from lerobot_predvla.policies.predvla.modeling_predvla import PredVLAPolicy, term_weights, training_terms

    path = trained / "checkpoints" / "last" / "pretrained_model"
    policy = PredVLAPolicy.from_pretrained(path)
    data, store = dx.TaskData.load(synthetic_dataset, policy), dx.load_store(path)
    weight_decay, clip = dx.optimizer_settings(path)
    momentum = dx.load_momentum(path, policy)
    assert momentum is not None and set(momentum) == {n for n, _ in policy.named_parameters()}
    report = dx.forces_report(policy, data, store, weight_decay, clip, momentum)
    w = report["weights"]
    prior = w["model.prior.0.weight"]["term_grad_norm"]
    assert prior["complexity"] > 0 and prior["action_nll"] == prior["vision_error"] == prior["proprio_error"] == 0
    head = w["model.v_head.0.weight"]["term_grad_norm"]
    assert head["vision_error"] > 0 and head["action_nll"] == head["proprio_error"] == head["complexity"] == 0

    episodes = torch.tensor(report["episodes"])
    seq = data.sequences.batch(episodes, torch.device("cpu"))
    model = policy.train().model
    terms = training_terms(model, policy.config, seq, store[episodes].transpose(0, 1),
                           model.language_term(seq["language"]))
    loss = sum(weight * terms[k] for k, weight in term_weights(policy.config).items())
    grads = torch.autograd.grad(loss, list(policy.parameters()), allow_unused=True)
    norms = {n: 0.0 if g is None else float(g.norm()) for (n, _), g in zip(policy.named_parameters(), grads,
                                                                           strict=True)}
    total = sum(v**2 for v in norms.values()) ** 0.5
    assert report["grad_norm"] == pytest.approx(total, rel=1e-4)
    assert report["clip_scale"] == pytest.approx(min(1.0, clip / total), rel=1e-4)
    p = dict(policy.named_parameters())["model.lang.weight"]
    expected = weight_decay * float(p.detach().norm()) / (report["clip_scale"] * norms["model.lang.weight"])
    assert w["model.lang.weight"]["decay_over_loss"] == pytest.approx(expected, rel=1e-3)
    assert all(r["momentum_decay_over_loss"] > 0 for r in w.values())

