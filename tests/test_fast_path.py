"""The fused recurrence (`PredictiveModel.rollout`) against the eager reference loop over `step`."""

import dataclasses
from functools import partial

import pytest
import torch
from rollout_checks import outputs_and_gradients

from benchmarks.bench_core import control_stream, randomised_model, training_data, training_loss
from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla import recurrence_cpp
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression, WindowAdam
from lerobot_predvla.policies.predvla.reference import reference_rollout

ABLATIONS = {
    "full": {}, "A2 no bottleneck": {"use_bottleneck": False}, "A3 no efference": {"use_efference_copy": False}
}


def loss_and_grads(model, rollout, data) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """Eq. 10 and its gradient with respect to the network and the posteriors."""
    c_q = data["c_q"].clone().requires_grad_(True)
    loss = training_loss(model, rollout, data, c_q)
    return loss, torch.autograd.grad(loss, [*model.parameters(), c_q])


@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
def test_training_loss_and_gradients_match_reference(overrides):
    model = randomised_model(PredVLAConfig(device="cpu", **overrides))
    data = training_data(model.config, batch=3, steps=24)
    loss, grads = loss_and_grads(model, model.rollout, data)
    ref_loss, ref_grads = loss_and_grads(model, partial(reference_rollout, model), data)
    assert abs(loss.item() - ref_loss.item()) < 1e-5
    for (name, _), g, ref in zip(model.named_parameters(), grads, ref_grads, strict=False):
        assert (g - ref).abs().max() < 1e-5, name
    assert (grads[-1] - ref_grads[-1]).abs().max() < 1e-5  # posteriors


@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
@pytest.mark.parametrize("with_posteriors", [True, False], ids=["c_q", "priors on the fly"])
def test_every_output_and_gradient_matches_reference_in_float64(overrides, with_posteriors):
    """All trajectory fields, the final state and every input's gradient, extra_ab included."""
    model = randomised_model(PredVLAConfig(device="cpu", **overrides)).double()
    g = torch.Generator().manual_seed(1)
    steps, batch = 9, 2
    language = torch.randn(batch, 64, generator=g, dtype=torch.float64)
    c_q = torch.randn(steps, batch, 256, generator=g, dtype=torch.float64).requires_grad_(with_posteriors)
    extra_ab = torch.randn(steps, batch, 256, generator=g, dtype=torch.float64, requires_grad=True)
    results = []
    for rollout in (model.rollout, partial(reference_rollout, model)):
        posteriors = c_q if with_posteriors else None
        traj = rollout(model.initial_state(batch), model.language_term(language), posteriors, extra_ab=extra_ab)
        results.append(outputs_and_gradients(traj, model, extra_ab, posteriors))
    for fast, ref in zip(*results, strict=True):
        torch.testing.assert_close(fast, ref, rtol=0, atol=1e-10)


def test_rollout_without_posteriors_is_the_prior_loop():
    """c_q=None: the posteriors equal the priors computed in module order, i.e. `step(..., u=None)`."""
    model = randomised_model(PredVLAConfig(device="cpu"))
    language = torch.randn(2, 64)
    traj = model.rollout(model.initial_state(2), model.language_term(language), steps=7)
    state, lang = model.initial_state(2), model.language_term(language)
    for t in range(7):
        state, _, prior = model.step(state, lang, None)
        assert (traj.a_hat[t] - state.a_hat).abs().max() < 1e-5
        assert (model.priors(traj)[t] - prior).abs().max() < 1e-5


@pytest.mark.parametrize("dtype, tolerance", [(torch.float64, 1e-10), (torch.float32, 1e-5)])
def test_error_regression_actions_match_reference(dtype, tolerance):
    """Sliding window included (more steps than W) in float64. In fp32 the two paths differ by summation
    order (~1e-7), which Adam's normalised steps amplify: a coordinate whose gradient is ~0 moves by +-lr
    on its sign. fp32 is therefore compared at the first control step only."""
    config = dataclasses.replace(PredVLAConfig(device="cpu"), er_window=4, er_iterations=3)
    model = randomised_model(config).to(dtype)
    steps = 6 if dtype == torch.float64 else 1
    language, obs = control_stream(config, batch=2, steps=steps)
    actions = []
    for rollout in (None, partial(reference_rollout, model)):
        er = ErrorRegression(model, rollout)
        actions.append(torch.stack([er(language.to(dtype), v.to(dtype), q.to(dtype)) for v, q in obs]))
    assert (actions[0] - actions[1]).abs().max() < tolerance


def test_window_adam_is_torch_adam():
    """Error regression's Adam on the window's posteriors takes exactly torch.optim.Adam's steps."""
    g = torch.Generator().manual_seed(3)
    ours = torch.randn(5, 2, 8, generator=g)
    theirs = ours.clone().requires_grad_(True)
    adam, reference = WindowAdam(ours, lr=0.05), torch.optim.Adam([theirs], lr=0.05)
    for _ in range(4):
        grad = torch.randn(ours.shape, generator=g)
        adam.step(grad)
        theirs.grad = grad.clone()
        reference.step()
        assert torch.equal(ours, theirs.detach())


def test_carried_window_adam_is_torch_adam_per_row():
    """er_adam_state="carried": each window row continues its own moments and step count, exactly as a
    torch.optim.Adam that has optimised that row alone for as many steps."""
    g = torch.Generator().manual_seed(4)
    history = [3, 1, 0]  # iterations each row has had before (the newest row: none)
    references = []
    for n in history:
        param = torch.randn(2, 8, generator=g).requires_grad_(True)
        adam = torch.optim.Adam([param], lr=0.05)
        for _ in range(n):
            param.grad = torch.randn(param.shape, generator=g)
            adam.step()
        references.append((param, adam))
    ours = torch.stack([p.detach().clone() for p, _ in references])
    state = [adam.state.get(p) for p, adam in references]
    exp_avg = torch.stack([s["exp_avg"] if s else torch.zeros(2, 8) for s in state])
    exp_avg_sq = torch.stack([s["exp_avg_sq"] if s else torch.zeros(2, 8) for s in state])
    window = WindowAdam(ours, lr=0.05, exp_avg=exp_avg, exp_avg_sq=exp_avg_sq, rows_steps=torch.tensor(history))
    for _ in range(3):
        grad = torch.randn(ours.shape, generator=g)
        window.step(grad)
        for (param, adam), row_grad in zip(references, grad.unbind(0), strict=True):
            param.grad = row_grad.clone()
            adam.step()
        # The bias corrections are computed as tensors here, as Python floats in torch's Adam: fp32 rounding.
        torch.testing.assert_close(ours, torch.stack([p.detach() for p, _ in references]), rtol=0, atol=1e-5)


def test_carried_adam_state_slides_with_the_window():
    """Carried moments and counts stay one per window step through the slide; the newest step starts from zero;
    the actions stay finite and differ from the fresh Adam's."""
    config = dataclasses.replace(PredVLAConfig(device="cpu"), er_window=3, er_iterations=2, er_adam_state="carried")
    model = randomised_model(config)
    language, obs = control_stream(config, batch=2, steps=5)
    er = ErrorRegression(model)
    carried = torch.stack([er(language, v, q) for v, q in obs])
    assert er.adam_steps == [6, 4, 2] and len(er.adam_exp_avg) == len(er.posteriors) == 3
    assert all(m.shape == p.shape for m, p in zip(er.adam_exp_avg_sq, er.posteriors, strict=True))
    model.config = dataclasses.replace(config, er_adam_state="fresh")
    fresh_er = ErrorRegression(model)
    fresh = torch.stack([fresh_er(language, v, q) for v, q in obs])
    assert fresh_er.adam_steps == [] and torch.isfinite(carried).all()
    torch.testing.assert_close(carried[0], fresh[0])  # one control step: no history to carry yet
    assert not torch.allclose(carried[-1], fresh[-1])
    with pytest.raises(ValueError, match="er_adam_state"):
        PredVLAConfig(device="cpu", er_adam_state="kept")


@pytest.mark.parametrize("backend", ["python", "cpp"])
@pytest.mark.parametrize("overrides", ABLATIONS.values(), ids=ABLATIONS.keys())
def test_shared_acting_chain_has_the_gradients_of_two_rollouts_in_float64(backend, overrides):
    """`posteriors_fit_actions=False`: the action term's chain from the posterior chain's forward
    (`rollout_shared_acting`) gives the losses and every gradient (network and posteriors) of rolling the chain out
    again with the posteriors detached, to float64 precision, on either backend."""
    if backend == "cpp" and recurrence_cpp.missing_toolchain() is not None:
        pytest.skip("no C++ toolchain")
    model = randomised_model(PredVLAConfig(device="cpu", recurrence_backend=backend, **overrides)).double()
    g = torch.Generator().manual_seed(2)
    steps, batch = 11, 3
    language = torch.randn(batch, 64, generator=g, dtype=torch.float64)
    c_q = torch.randn(steps, batch, 256, generator=g, dtype=torch.float64)
    vision = torch.randn(steps, batch, model.config.vision_dim, generator=g, dtype=torch.float64)
    proprio = torch.randn(steps, batch, model.config.proprio_dim, generator=g, dtype=torch.float64)
    action = torch.rand(steps, batch, model.config.action_dim, generator=g, dtype=torch.float64) * 1.8 - 0.9

    def loss_and_grads(shared: bool) -> tuple[torch.Tensor, list[torch.Tensor]]:
        posteriors = c_q.clone().requires_grad_(True)
        start, lang = model.initial_state(batch), model.language_term(language)
        if shared:
            traj, acting = model.rollout_shared_acting(start, lang, posteriors)
        else:
            traj, acting = model.rollout(start, lang, posteriors), model.rollout(start, lang, posteriors.detach())
        eps_v, eps_q = model.prediction_errors(traj, vision, proprio)
        complexity = model.complexity(posteriors, model.priors(traj), model.config.complexity_weights)
        loss = eps_v.mean() + eps_q.mean() + complexity.mean() + model.action_nll(acting, action).mean()
        return loss, torch.autograd.grad(loss, [*model.parameters(), posteriors], allow_unused=True)

    loss, grads = loss_and_grads(shared=True)
    ref_loss, ref_grads = loss_and_grads(shared=False)
    torch.testing.assert_close(loss, ref_loss, rtol=0, atol=1e-12)
    names = [n for n, _ in model.named_parameters()] + ["posteriors"]
    for name, g_shared, g_ref in zip(names, grads, ref_grads, strict=True):
        assert (g_shared is None) == (g_ref is None), name
        if g_ref is not None:
            torch.testing.assert_close(g_shared, g_ref, rtol=0, atol=1e-10, msg=name)
    # The action term's gradient reaches the network but not the posteriors, as it would with one rollout for both.
    posteriors = c_q.clone().requires_grad_(True)
    joint = model.rollout(model.initial_state(batch), model.language_term(language), posteriors)
    eps_v, eps_q = model.prediction_errors(joint, vision, proprio)
    complexity = model.complexity(posteriors, model.priors(joint), model.config.complexity_weights)
    joint_loss = eps_v.mean() + eps_q.mean() + complexity.mean() + model.action_nll(joint, action).mean()
    assert (torch.autograd.grad(joint_loss, posteriors)[0] - grads[-1]).abs().max() > 1e-6
