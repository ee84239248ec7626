"""Equation-level checks of the PredVLA policy: parameters, open loop, priors, error regression, masks, I/O."""

import dataclasses

import pytest
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.datasets import LeRobotDatasetMetadata
from lerobot.policies.factory import make_policy
from safetensors import safe_open

from lerobot_predvla import PredVLAConfig, PredVLAPolicy
from lerobot_predvla.policies.predvla.configuration_predvla import LONG_HORIZON_TAU
from lerobot_predvla.policies.predvla.modeling_predvla import term_weights, training_terms
from lerobot_predvla.policies.predvla.posterior_store import POSTERIOR_STORE_FILE


def observation(batch: int = 1, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    return {
        "observation.language_features": torch.randn(batch, 64, generator=g),
        "observation.vision_features": torch.randn(batch, 192, generator=g),
        "observation.state": torch.randn(batch, 9, generator=g),
    }


def stream(steps: int, batch: int = 1, seed: int = 0, language_seed: int = 0) -> list[dict[str, torch.Tensor]]:
    language = observation(batch, language_seed)["observation.language_features"]
    return [{**observation(batch, seed * 1000 + t), "observation.language_features": language} for t in range(steps)]


def randomised_policy(**overrides) -> PredVLAPolicy:
    """A policy whose biases and initial states are non-zero too, so no pathway is trivially silent."""
    torch.manual_seed(0)
    policy = PredVLAPolicy(PredVLAConfig(device="cpu", **overrides))
    with torch.no_grad():
        for p in policy.model.parameters():
            if p.dim() == 1:
                p.normal_(0, 0.3)
    return policy.eval()


def run(policy: PredVLAPolicy, observations: list[dict]) -> torch.Tensor:
    policy.reset()
    with torch.inference_mode():  # as lerobot-eval calls it
        return torch.stack([policy.select_action(o) for o in observations])


@pytest.fixture(scope="module")
def trained_policy(synthetic_dataset) -> PredVLAPolicy:
    """A policy built like lerobot-train builds it, after a few optimiser steps."""
    meta = LeRobotDatasetMetadata("local/predvla_synthetic", root=synthetic_dataset)
    policy = make_policy(PredVLAConfig(device="cpu", sequence_length=32, er_window=8, er_iterations=3), ds_meta=meta)
    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=1e-3)
    for step in range(3):
        loss, _ = policy.forward({"episode_index": torch.tensor([step, step + 1, 5])})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        policy.update()  # the posteriors' row-wise Adam, as lerobot-train calls it
    return policy.eval()


def test_parameter_count_matches_table_1():
    policy = PredVLAPolicy(PredVLAConfig())
    assert sum(p.numel() for p in policy.parameters() if p.requires_grad) == 675_732
    assert policy.posterior_store is None  # no dataset: the controller only


@pytest.mark.parametrize("flush", [True, False])
def test_a_cpu_policy_flushes_subnormal_floats_unless_asked_not_to(flush):
    subnormal = torch.tensor([1e-39])
    torch.set_flush_denormal(False)
    try:
        PredVLAPolicy(PredVLAConfig(device="cpu", flush_denormal=flush))
        assert bool((subnormal * 1.0 == 0).item()) is flush
    finally:
        torch.set_flush_denormal(False)


def features(vision: int, language: int, state: int, action: int) -> tuple[dict, dict]:
    """Input and output features as `make_policy` passes a dataset's (images and other columns included)."""
    inputs = {
        "observation.vision_features": PolicyFeature(FeatureType.STATE, (vision,)),
        "observation.language_features": PolicyFeature(FeatureType.STATE, (language,)),
        "observation.state": PolicyFeature(FeatureType.STATE, (state,)),
        "observation.images.front": PolicyFeature(FeatureType.VISUAL, (3, 8, 8)),
    }
    return inputs, {"action": PolicyFeature(FeatureType.ACTION, (action,))}


@pytest.mark.parametrize("sizes", [(192, 9, 7), (192, 8, 7), (96, 6, 6), (288, 14, 12)])
def test_sizes_follow_the_dataset_features(sizes):
    """Any state and action dimension and any number of cameras; Table 1's layout keeps 675,732 parameters."""
    vision, state, action = sizes
    inputs, outputs = features(vision, 64, state, action)
    config = PredVLAConfig(input_features=inputs, output_features=outputs)
    policy = PredVLAPolicy(config)
    assert (config.num_cameras, config.proprio_dim, config.action_dim) == (vision // 96, state, action)
    assert sorted(config.input_features) == sorted(k for k in inputs if "images" not in k)
    count = sum(p.numel() for p in policy.parameters())
    assert (count == 675_732) == (sizes == (192, 9, 7))
    actions = run(policy, [{"observation.vision_features": torch.randn(2, vision),
                            "observation.language_features": torch.randn(2, 64),
                            "observation.state": torch.randn(2, state)}])
    assert actions.shape == (1, 2, action) and torch.isfinite(actions).all()


def test_unusable_feature_sizes_are_rejected():
    with pytest.raises(ValueError, match="not a multiple of vision_dim_per_camera=96"):
        PredVLAConfig(input_features=features(100, 64, 9, 7)[0], output_features=features(100, 64, 9, 7)[1]
                      ).validate_features()
    with pytest.raises(ValueError, match="language_dim is 64"):
        PredVLAConfig(input_features=features(192, 32, 9, 7)[0], output_features=features(192, 32, 9, 7)[1]
                      ).validate_features()


def test_defaults_match_tables_1_and_2():
    c = PredVLAConfig()
    assert (c.language_dim, c.vision_dim_per_camera, c.num_cameras, c.vision_dim, c.proprio_dim, c.action_dim) == (
        64, 96, 2, 192, 9, 7)
    assert c.module_dims == (64, 256, 256, 256) and c.latent_dim == 64 and c.bottleneck_dim == 32
    assert (c.num_mixtures, c.min_action_scale, c.tau, c.visual_refresh_interval) == (5, 0.05, (16, 8, 5, 2), 4)
    assert (c.optimizer_lr, c.posterior_lr, c.optimizer_weight_decay) == (6e-5, 1e-2, 1e-4)
    assert (c.train_batch_size, c.train_steps, c.sequence_length) == (32, 30_000, 200)
    assert (c.lambda_v, c.lambda_q, c.lambda_a, c.complexity_weights) == (1, 1, 1, (0.05, 0.02, 0.02, 0.01))
    assert c.complexity_reduction == "sum"  # Eq. 10: C carries no mask-normalised bar
    assert (c.er_window, c.er_iterations, c.er_lr, c.er_complexity_weight) == (40, 10, 0.05, 1.0)
    assert c.get_scheduler_preset() is None and c.get_optimizer_preset().grad_clip_norm > 0
    long = PredVLAConfig.long_horizon()
    assert long.tau == LONG_HORIZON_TAU == (30, 14, 8, 2) and long.sequence_length == 500


def test_open_loop_is_exact_at_zero_iterations():
    """n_itr = 0: actions are the prior rollout and do not depend on vision or proprioception at all."""
    policy = randomised_policy(er_iterations=0)
    a = run(policy, stream(12, seed=1))
    b = run(policy, stream(12, seed=2))  # same language, other observations
    assert torch.equal(a, b)
    # The same actions from the generative model alone: posterior = prior at every step.
    model = policy.model
    lang = model.language_term(stream(1)[0]["observation.language_features"])
    state, manual = model.initial_state(1), []
    with torch.no_grad():
        for _ in range(12):
            state, params, _ = model.step(state, lang, None)
            manual.append(state.a_hat)
    assert torch.equal(a, torch.stack(manual))
    # With error regression the observations do matter.
    closed = randomised_policy(er_iterations=2, er_window=6)
    assert not torch.allclose(run(closed, stream(12, seed=1)), run(closed, stream(12, seed=2)))


def test_newest_posterior_starts_at_its_prior():
    policy = randomised_policy(er_iterations=3, er_window=5)
    er = policy.error_regression
    for obs in stream(9):  # past the window length, so the window has slid
        feed(er, obs)
        c_q = torch.stack(er.posteriors)
        with torch.no_grad():
            priors = policy.model.priors(policy.model.rollout(er.start_state, er.lang_term, c_q))
        torch.testing.assert_close(c_q[-1], priors[-1], rtol=0, atol=1e-6)
        assert len(er.posteriors) <= 5
        er.infer()
        er.act()
        assert not torch.allclose(torch.stack(er.posteriors)[-1], priors[-1])  # inference moved it


def feed(er, obs: dict[str, torch.Tensor]) -> None:
    er.observe(*(obs[k] for k in ("observation.language_features", "observation.vision_features", "observation.state")))


def test_free_energy_gradient_matches_finite_differences():
    policy = randomised_policy(er_iterations=1, er_window=4).double()
    er = policy.error_regression
    for obs in stream(6):
        feed(er, {k: v.double() for k, v in obs.items()})
    c_q = torch.stack(er.posteriors).clone().requires_grad_(True)

    def free_energy(c: torch.Tensor) -> torch.Tensor:
        return er.free_energy(policy.model.rollout(er.start_state, er.lang_term, c), c)

    (grad,) = torch.autograd.grad(free_energy(c_q), c_q)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for _ in range(4):  # directional derivatives along random directions, central differences
            v = torch.randn(c_q.shape, generator=g, dtype=c_q.dtype)
            numeric = (free_energy(c_q + 1e-6 * v) - free_energy(c_q - 1e-6 * v)) / 2e-6
            torch.testing.assert_close((grad * v).sum(), numeric, rtol=1e-6, atol=1e-8)


def test_plain_gradient_descent_takes_section_3_5s_step():
    """`er_optimizer="gd"`: one iteration is c_q - eta dE/dc_q, with dE/dc_q the free energy's full gradient."""
    policy = randomised_policy(er_iterations=1, er_window=4, er_optimizer="gd", er_lr=0.01).double()
    er = policy.error_regression
    for obs in stream(6):
        feed(er, {k: v.double() for k, v in obs.items()})
    c_q = torch.stack(er.posteriors).clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(er.free_energy(policy.model.rollout(er.start_state, er.lang_term, c_q), c_q), c_q)
    er.infer()
    torch.testing.assert_close(torch.stack(er.posteriors), (c_q - 0.01 * grad).detach())


@pytest.mark.parametrize("detach", [False, True])
def test_detached_priors_make_the_complexity_pull_the_posteriors_only(detach):
    """With the prediction errors weighted 0, dE/dc_q is w_ER (c_q - c_p) exactly when the priors are detached;
    through the priors, the later steps' priors pull back on the earlier posteriors and it differs."""
    policy = randomised_policy(er_iterations=1, er_window=4, er_detach_priors=detach, er_lambda_v=0.0,
                               er_lambda_q=0.0).double()
    er = policy.error_regression
    for obs in stream(6):
        feed(er, {k: v.double() for k, v in obs.items()})
    c_q = (torch.stack(er.posteriors) + 0.1).requires_grad_(True)
    traj = policy.model.rollout(er.start_state, er.lang_term, c_q)
    (grad,) = torch.autograd.grad(er.free_energy(traj, c_q), c_q)
    own = policy.config.er_complexity_weight * (c_q - policy.model.priors(traj)).detach()
    assert torch.allclose(grad, own) == detach


def test_error_regression_lowers_window_free_energy():
    """Every control step's inference ends below where it started.

    The network is made responsive to its latents (U scaled up, as training does) and the step is small:
    Adam's sign-like first updates move every coordinate by the step size, and on an untrained network
    the unit-weight complexity curvature outweighs the first-order decrease at the paper's 0.05.
    """
    policy = randomised_policy(er_iterations=10, er_window=8, er_lr=0.005)
    with torch.no_grad():
        for latent_map in policy.model.latent:
            latent_map.weight.mul_(3.0)
    er = policy.error_regression
    for t, obs in enumerate(stream(12)):
        feed(er, obs)
        before = er.window_free_energy()
        er.infer()
        after = er.window_free_energy()
        assert after < before, f"step {t}: free energy {before:.5f} -> {after:.5f}"
        er.act()


def test_batched_environments_match_single_runs():
    policy = randomised_policy(er_iterations=3, er_window=6)
    both = run(policy, stream(8, batch=2, seed=3))
    for i in range(2):
        single = [{k: v[i : i + 1] for k, v in o.items()} for o in stream(8, batch=2, seed=3)]
        # Losses are separable per environment; only matmul rounding differs between batch sizes, and
        # Adam's normalised steps amplify it near zero gradients.
        torch.testing.assert_close(run(policy, single)[:, 0], both[:, i], rtol=1e-3, atol=1e-3)


@pytest.mark.parametrize("er_adam_state", ["fresh", "carried"])
def test_a_rows_actions_do_not_depend_on_what_the_other_rows_see(er_adam_state):
    """lerobot-eval steps the whole batch until its last episode ends, so the rows of finished episodes keep feeding
    the policy: today's discarded episodes, or their terminal observation again once `predvla_libero` freezes them.
    Neither may change another row's actions, bit for bit (same batch size, so the same kernels)."""
    policy = randomised_policy(er_iterations=3, er_window=6, er_adam_state=er_adam_state)
    observations = stream(10, batch=3, seed=3)
    other = [{k: v.clone() for k, v in o.items()} for o in observations]
    for t, o in enumerate(other[4:], start=4):
        for key, value in o.items():
            if key != "observation.language_features":
                value[1] = observation(3, 500 + t)[key][1]  # row 1: another episode
                value[2] = observations[4][key][2]  # row 2: its step-4 observation again (a frozen replay)
    reference, changed = run(policy, observations), run(policy, other)
    assert torch.equal(reference[:, 0], changed[:, 0])
    assert not torch.equal(reference[5:, 1:], changed[5:, 1:])


def test_reset_clears_the_window():
    policy = randomised_policy(er_iterations=2, er_window=4)
    first = run(policy, stream(6, seed=4))
    run(policy, stream(3, seed=5))
    assert torch.equal(run(policy, stream(6, seed=4)), first)


def test_padded_and_non_refresh_steps_contribute_nothing(trained_policy):
    policy = trained_policy.train()
    seq = policy.sequences
    batch = {"episode_index": torch.tensor([0, 3, 6])}

    def loss_and_grads():
        policy.zero_grad()
        loss, _ = policy.forward(batch)
        loss.backward()
        return loss.detach(), [p.grad.clone() for p in policy.parameters()]

    reference = loss_and_grads()
    saved = dataclasses.replace(seq, vision=seq.vision.clone(), state=seq.state.clone(), action=seq.action.clone())
    steps = torch.arange(seq.vision.shape[1])
    padded = steps[None, :] >= seq.length[:, None]
    non_refresh = (steps % policy.config.visual_refresh_interval != 0)[None, :].expand_as(padded)
    seq.vision[non_refresh | padded] = 100.0
    seq.state[padded] = -50.0
    seq.action[padded] = 0.9
    perturbed = loss_and_grads()
    assert torch.equal(reference[0], perturbed[0])
    assert all(torch.equal(a, b) for a, b in zip(reference[1], perturbed[1], strict=True))
    seq.vision[:, 4] += 1.0  # a fresh, valid step: now the loss must change
    assert not torch.equal(loss_and_grads()[0], reference[0])
    policy.sequences = saved
    policy.posterior_store.discard_pending()  # gradients for inspection only: not a training step
    policy.eval()


def test_training_skips_the_padding_after_the_longest_episode(trained_policy):
    """The batch is cut after its longest episode (`trim_padding`): the loss, the network's gradient and the
    posteriors' gradient equal those of the recurrence run over the whole padded sequence."""
    policy, episodes = trained_policy.train(), torch.tensor([0, 3, 6])
    cfg, model = policy.config, policy.model
    assert int(policy.sequences.length[episodes].max()) < cfg.sequence_length  # there is padding to skip

    def loss_and_grads(trim: bool):
        policy.zero_grad()
        if trim:
            loss, _ = policy.forward({"episode_index": episodes})
        else:
            seq = policy.sequences.batch(episodes, torch.device("cpu"))
            c_q = policy.posterior_store.gather(episodes)
            terms = training_terms(model, cfg, seq, c_q, model.language_term(seq["language"]))
            loss = sum(w * terms[name] for name, w in term_weights(cfg).items())
        loss.backward()
        rows = policy.posterior_store.pending_gradients()[-1][1]
        policy.posterior_store.discard_pending()  # gradients for inspection only: not a training step
        return loss.detach(), [p.grad.clone() for p in policy.parameters()], rows.grad.clone()

    full, trimmed = loss_and_grads(trim=False), loss_and_grads(trim=True)
    torch.testing.assert_close(trimmed[0], full[0], rtol=1e-6, atol=1e-7)
    for a, b in zip(trimmed[1], full[1], strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(trimmed[2], full[2], rtol=1e-5, atol=1e-7)
    assert bool(full[2][:, -1].abs().sum() == 0)  # the padded posteriors get no gradient either way
    policy.eval()


def test_training_complexity_is_summed_over_each_sequence(trained_policy):
    """Eq. 10 puts no bar on C: C = sum over a sequence's valid steps of C_t (Eq. 8), averaged over the batch."""
    policy, episodes = trained_policy, torch.tensor([0, 3, 6])
    weights = torch.tensor(policy.config.complexity_weights)
    with torch.no_grad():
        _, terms = policy.forward({"episode_index": episodes})
        seq = policy.sequences.batch(episodes, torch.device("cpu"))
        c_q = policy.posterior_store.gather(episodes)
        traj = policy.model.rollout(
            policy.model.initial_state(len(episodes)), policy.model.language_term(seq["language"]), c_q
        )
        c_p = policy.model.priors(traj)
    per_module = (c_q - c_p).unflatten(-1, (4, policy.config.latent_dim)).pow(2).sum(-1)  # (T, B, 4)
    c_t = 0.5 * (per_module * weights).sum(-1)
    expected = (c_t * seq["valid"]).sum(0).mean()
    assert terms["complexity"] == pytest.approx(expected.item(), rel=1e-5)
    policy.config.complexity_reduction = "mean"  # the per-step reading, kept as an option
    try:
        with torch.no_grad():
            _, mean_terms = policy.forward({"episode_index": episodes})
    finally:
        policy.config.complexity_reduction = "sum"
    assert mean_terms["complexity"] == pytest.approx((c_t * seq["valid"]).sum().item() / seq["valid"].sum().item(),
                                                     rel=1e-5)
    with pytest.raises(ValueError, match="complexity_reduction"):
        PredVLAConfig(complexity_reduction="max")


def test_the_optimizer_gets_the_network_and_update_steps_the_batch_posteriors(trained_policy):
    groups = trained_policy.get_optim_params()
    assert len(groups) == 1 and sum(p.numel() for p in groups[0]["params"]) == 675_732
    store = trained_policy.posterior_store
    assert store.latents.shape == (8, 32, 256) and store.lr == 1e-2
    # Batches [0,1,5], [1,2,5], [2,3,5]: each row stepped once per batch it was in, the others never.
    assert store.steps.tolist() == [1, 2, 2, 1, 0, 3, 0, 0]
    assert store.latents[[0, 1, 2, 3, 5]].abs().sum() > 0 and store.latents[[4, 6, 7]].abs().sum() == 0


def test_save_and_load_reproduce_actions(trained_policy, tmp_path):
    trained_policy.save_pretrained(tmp_path)
    with safe_open(tmp_path / "model.safetensors", "pt") as f:
        keys = list(f.keys())
    assert keys and not any("posterior" in k for k in keys)  # never in the weights file
    assert (tmp_path / POSTERIOR_STORE_FILE).is_file()  # but in the training checkpoint
    loaded = PredVLAPolicy.from_pretrained(tmp_path)
    assert loaded.posterior_store is None
    obs = stream(12, seed=7)
    assert torch.equal(run(trained_policy, obs), run(loaded, obs))


def test_lr_decay_option_decays_the_network_rate_along_a_cosine():
    """`lr_decay_to` (a CPU-recipe option; Table 2 is constant): cosine from optimizer_lr to the value; the
    posteriors' rate (their own row-wise Adam) stays posterior_lr."""
    import torch

    config = PredVLAConfig(optimizer_lr=1e-3, lr_decay_to=1e-4)
    optimizer = torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))], lr=config.optimizer_lr)
    scheduler = config.get_scheduler_preset().build(optimizer, num_training_steps=100)
    rates = []
    for _ in range(101):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    assert rates[0] == pytest.approx(1e-3) and rates[50] == pytest.approx(5.5e-4) and rates[100] == pytest.approx(1e-4)


def test_open_loop_term_trains_the_prior_chain_on_the_same_episodes(trained_policy):
    """`open_loop_weight` beta (a CPU-recipe option; 0 is Eq. 10): loss = Eq. 10 + beta x (lambda_v eps_v +
    lambda_q eps_q + lambda_a NLL) on the exact open-loop rollout (every posterior at its prior), and its
    gradient reaches the priors and W_lang but never the posteriors."""
    from lerobot_predvla.policies.predvla.reference import reference_rollout

    policy, episodes = trained_policy.train(), torch.tensor([1, 4, 6])
    cfg = policy.config
    with torch.no_grad():
        base, base_terms = policy.forward({"episode_index": episodes})
    assert not any(k.startswith("open_loop") for k in base_terms)
    cfg.open_loop_weight = 0.5
    try:
        policy.zero_grad()
        loss, terms = policy.forward({"episode_index": episodes})
        loss.backward()
        seq = policy.sequences.batch(episodes, torch.device("cpu"))
        with torch.no_grad():
            model = policy.model
            ref = reference_rollout(model, model.initial_state(3), model.language_term(seq["language"]),
                                    steps=seq["valid"].shape[0])
            nll = model.action_nll(ref, seq["action"])
            _, eps_q = model.prediction_errors(ref, seq["vision"], seq["state"])
        valid = seq["valid"]
        assert terms["open_loop_action_nll"] == pytest.approx((nll * valid).sum().item() / valid.sum().item(),
                                                              rel=1e-4)
        assert terms["open_loop_proprio_error"] == pytest.approx(
            (eps_q * valid).sum().item() / valid.sum().item(), rel=1e-4)
        extra = terms["open_loop_vision_error"] + terms["open_loop_proprio_error"] + terms["open_loop_action_nll"]
        assert loss.item() == pytest.approx(base.item() + 0.5 * extra, rel=1e-5)
        # The open-loop chain uses no posterior, so the posteriors' gradient is Eq. 10's alone.
        [(_, rows)] = policy.posterior_store.pending_gradients()
        post_grad = rows.grad.clone()
        cfg.open_loop_weight = 0.0
        policy.zero_grad()
        policy.posterior_store.discard_pending()
        policy.forward({"episode_index": episodes})[0].backward()
        [(_, rows)] = policy.posterior_store.pending_gradients()
        assert torch.allclose(post_grad, rows.grad, atol=1e-6)
        assert policy.model.lang.weight.grad is not None
    finally:
        cfg.open_loop_weight = 0.0
        policy.posterior_store.discard_pending()  # gradients for inspection only: not a training step
        policy.eval()
    with pytest.raises(ValueError, match="open_loop_weight"):
        PredVLAConfig(open_loop_weight=-1.0)


def test_posteriors_that_do_not_fit_the_actions_get_the_gradient_of_what_error_regression_sees(trained_policy):
    """`posteriors_fit_actions=False` (a departure from Eq. 10): the same losses and the same network gradients, but
    the posteriors' gradient is that of the prediction errors and the complexity only (as with lambda_a = 0)."""
    policy, episodes = trained_policy.train(), torch.tensor([1, 4, 6])
    cfg = policy.config

    def gradients() -> tuple[float, dict, torch.Tensor, dict]:
        policy.zero_grad()
        policy.posterior_store.discard_pending()
        loss, terms = policy.forward({"episode_index": episodes})
        loss.backward()
        [(_, rows)] = policy.posterior_store.pending_gradients()
        weights = {n: p.grad.clone() for n, p in policy.model.named_parameters() if p.grad is not None}
        return loss.item(), terms, rows.grad.clone(), weights

    try:
        loss, terms, post_grad, weights = gradients()
        cfg.posteriors_fit_actions = False
        loss_free, terms_free, post_free, weights_free = gradients()
        cfg.posteriors_fit_actions, cfg.lambda_a = True, 0.0
        _, _, post_no_action, _ = gradients()
    finally:
        cfg.posteriors_fit_actions, cfg.lambda_a = True, 1.0
        policy.posterior_store.discard_pending()  # gradients for inspection only: not a training step
        policy.eval()
    assert loss_free == pytest.approx(loss, rel=1e-6) and terms_free == pytest.approx(terms, rel=1e-6)
    assert weights_free.keys() == weights.keys()
    assert all(torch.allclose(weights_free[n], weights[n], atol=1e-6, rtol=1e-4) for n in weights)
    assert torch.allclose(post_free, post_no_action, atol=1e-7) and not torch.allclose(post_free, post_grad, atol=1e-7)


@pytest.mark.parametrize("omp", [None, "2"])
def test_acting_on_the_cpu_runs_on_one_thread_unless_omp_num_threads_is_set(monkeypatch, omp):
    """select_action runs error regression on one torch thread on the CPU (small matmuls stall on shared cores with
    more) and gives torch its setting back; OMP_NUM_THREADS, where set, keeps torch's own count."""
    if omp is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", omp)
    policy = randomised_policy()
    policy.reset()
    seen = []

    class Spy:
        def __init__(self, inner):
            self.inner = inner

        def __call__(self, *args):
            seen.append(torch.get_num_threads())
            return self.inner(*args)

        def __getattr__(self, name):
            return getattr(self.inner, name)

    policy.error_regression = Spy(policy.error_regression)
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with torch.inference_mode():
            policy.select_action(stream(1)[0])
        assert seen == [1 if omp is None else 2]
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(threads)
