"""PredVLA on a CUDA device computes what it computes on the CPU (skipped without one).

Both devices run in float64, so that the comparison is of the arithmetic: in float32 the two devices' rounding
differs, and error regression's Adam steps (normalised per coordinate) carry such differences into the actions
(2e-4 between float32 and float64 on the CPU alone, over the 48 steps below).
"""

import copy

import pytest
import torch
from test_policy import randomised_policy, run, stream

from lerobot_predvla.policies.predvla.modeling_predvla import term_weights, training_terms

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")


def sequences(policy, batch: int, steps: int) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """Whole episodes as `EpisodeSequences.batch` gives them (time-major; the last steps of one padded), and their
    posteriors, in float64 on the CPU."""
    cfg = policy.config
    g = torch.Generator().manual_seed(0)
    valid = torch.ones(steps, batch, dtype=torch.bool)
    valid[steps - 5:, 0] = False
    seq = {"language": torch.randn(batch, cfg.language_dim, generator=g, dtype=torch.float64),
           "vision": torch.randn(steps, batch, cfg.vision_dim, generator=g, dtype=torch.float64),
           "state": torch.randn(steps, batch, cfg.proprio_dim, generator=g, dtype=torch.float64),
           "action": torch.rand(steps, batch, cfg.action_dim, generator=g, dtype=torch.float64) * 1.8 - 0.9,
           "valid": valid}
    return seq, 0.3 * torch.randn(steps, batch, 4 * cfg.latent_dim, generator=g, dtype=torch.float64)


def loss_and_gradients(model, cfg, seq: dict, c_q: torch.Tensor, device: str):
    model = copy.deepcopy(model).to(device)
    seq = {k: v.to(device) for k, v in seq.items()}
    c_q = c_q.to(device, copy=True).requires_grad_(True)  # a leaf of its own on either device
    terms = training_terms(model, cfg, seq, c_q, model.language_term(seq["language"]))
    loss = sum(weight * terms[name] for name, weight in term_weights(cfg).items())
    loss.backward()
    return loss.detach().cpu(), c_q.grad.cpu(), {
        n: p.grad.cpu() for n, p in model.named_parameters() if p.grad is not None}


def assert_gradient_close(actual: torch.Tensor, expected: torch.Tensor, name: str, rtol: float,
                          atol_per_largest: float) -> None:
    atol = atol_per_largest * float(expected.abs().max())
    torch.testing.assert_close(actual, expected, rtol=rtol, atol=atol, msg=lambda m: f"{name}: {m}")


def test_training_loss_and_its_gradients_match_the_cpu():
    """Eq. 10 at Table 2's sizes on 3 episodes of 64 steps: loss, posterior and weight gradients."""
    policy = randomised_policy(recurrence_backend="python").double()
    seq, c_q = sequences(policy, batch=3, steps=64)
    on_cpu = loss_and_gradients(policy.model, policy.config, seq, c_q, "cpu")
    on_cuda = loss_and_gradients(policy.model, policy.config, seq, c_q, "cuda")
    assert torch.isfinite(on_cuda[0]) and on_cuda[0].item() != 0.0
    torch.testing.assert_close(on_cuda[0], on_cpu[0], rtol=1e-10, atol=1e-10)
    # Summation order differs between the devices and 64 steps of BPTT amplify it: in float64 that left 6e-9 of
    # the posterior gradient's largest entry on an H100 (float64's resolution is 1e-16). Float32 arithmetic on one
    # device, amplified alike, would leave far more than the 1e-6 allowed.
    close = {"rtol": 1e-5, "atol_per_largest": 1e-6}
    assert_gradient_close(on_cuda[1], on_cpu[1], "c_q", **close)
    assert on_cuda[2].keys() == on_cpu[2].keys() and len(on_cpu[2]) > 10
    for name, grad in on_cpu[2].items():
        assert_gradient_close(on_cuda[2][name], grad, name, **close)


def test_error_regression_acts_alike_on_cuda():
    """48 control steps (the 40-step window fills, then slides) with Table 2's error regression: the same actions."""
    policy = randomised_policy(recurrence_backend="python").double()
    observations = [{k: v.double() if v.is_floating_point() else v for k, v in o.items()} for o in stream(48)]
    on_cpu = run(policy, observations)
    cuda = copy.deepcopy(policy).to("cuda")
    cuda.config.device = "cuda"
    on_cuda = run(cuda, [{k: v.to("cuda") for k, v in o.items()} for o in observations])
    assert on_cuda.is_cuda and torch.isfinite(on_cuda).all()
    torch.testing.assert_close(on_cuda.cpu(), on_cpu, rtol=1e-6, atol=1e-7)
