"""bfloat16 mixed precision in training (`--policy.use_amp=true`, opt-in): the loss and every gradient of one step
agree with float32 within bfloat16's rounding, and error regression ignores the autocast."""

import torch
from test_policy import randomised_policy, run, stream

from benchmarks.bench_core import randomised_model, training_data, training_loss
from lerobot_predvla import PredVLAConfig

# Measured on the Table 2 model at batch 16 x 200 steps: loss within 3e-4 relative, gradient cosine > 0.9999.
LOSS_RTOL = 1e-2
GRADIENT_COSINE = 0.999


def loss_and_grads(model, data, amp: bool) -> tuple[float, torch.Tensor, torch.Tensor]:
    c_q = data["c_q"].clone().requires_grad_(True)
    with torch.autocast("cpu", dtype=torch.bfloat16, enabled=amp):
        loss = training_loss(model, model.rollout, data, c_q)
    grads = torch.autograd.grad(loss, [*model.parameters(), c_q])
    return loss.item(), torch.cat([g.flatten() for g in grads[:-1]]), grads[-1]


def test_bf16_training_step_agrees_with_fp32():
    model = randomised_model(PredVLAConfig(device="cpu"))
    data = training_data(model.config, batch=4, steps=48)
    loss32, net32, post32 = loss_and_grads(model, data, amp=False)
    loss16, net16, post16 = loss_and_grads(model, data, amp=True)
    assert abs(loss16 - loss32) <= LOSS_RTOL * abs(loss32)
    for g16, g32 in ((net16, net32), (post16.flatten(), post32.flatten())):
        assert g16.dtype == torch.float32  # gradients reach the float32 parameters and posteriors in float32
        assert torch.nn.functional.cosine_similarity(g16, g32, dim=0) > GRADIENT_COSINE
        assert 0.99 < (g16.norm() / g32.norm()).item() < 1.01
    assert loss16 != loss32  # the autocast did take effect


def test_amp_is_opt_in():
    assert PredVLAConfig(device="cpu").use_amp is False  # float32 by default (docs/speed.md, "Mixed precision")


def test_error_regression_runs_in_float32_under_autocast():
    policy = randomised_policy()
    observations = stream(12)
    expected = run(policy, observations)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        actions = run(policy, observations)
    torch.testing.assert_close(actions, expected, rtol=0, atol=0)
