"""The error-regression tracer (`predvla trace`) reads the steps of `ErrorRegression` and changes none of them."""

import dataclasses
import json

import torch

from benchmarks.bench_core import control_stream, randomised_model
from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression
from lerobot_predvla.policies.predvla.trace import TraceRecorder


def act(model, language, obs, tracer=None) -> torch.Tensor:
    er = ErrorRegression(model)
    ErrorRegression.tracer = tracer
    try:
        return torch.stack([er(language, v, q) for v, q in obs])
    finally:
        ErrorRegression.tracer = None


def test_tracing_changes_no_action_and_measures_the_posterior_moves():
    config = dataclasses.replace(PredVLAConfig(device="cpu"), er_window=3, er_iterations=2)
    model = randomised_model(config).to(torch.float64)
    language, obs = control_stream(config, batch=2, steps=5)
    language, obs = language.double(), [(v.double(), q.double()) for v, q in obs]
    recorder = TraceRecorder()
    assert torch.equal(act(model, language, obs, recorder), act(model, language, obs))

    # The newest step's move, recomputed: one control step by hand from the same state, its posteriors' change.
    er = ErrorRegression(model)
    for v, q in obs[:4]:
        er(language, v, q)
    er.observe(language, *obs[4])
    before = torch.stack(er.posteriors)
    er.infer()
    change = (er.posteriors[-1] - before[-1]).unflatten(-1, (4, config.latent_dim)).norm(dim=-1)
    episodes = recorder.episodes()
    assert len(episodes) == 2 and episodes[0]["steps"] == [1, 2, 3, 4, 5]
    for i, episode in enumerate(episodes):
        assert torch.allclose(torch.tensor(episode["move_newest"][4]), change[i].float(), atol=1e-6)
        assert len(episode["move_window"]) == 5 and len(episode["move_window"][0]) == 4


def test_open_loop_is_traced_without_moves_and_batches_split_into_episodes():
    config = dataclasses.replace(PredVLAConfig(device="cpu"), er_iterations=0)
    model = randomised_model(config)
    recorder = TraceRecorder()
    for batch in (3, 2):  # two lerobot-eval batches: each starts a fresh ErrorRegression at step 1
        language, obs = control_stream(config, batch=batch, steps=4)
        actions = act(model, language, obs, recorder)
    episodes = recorder.episodes()
    assert len(episodes) == 5 and all(ep["steps"] == [1, 2, 3, 4] for ep in episodes)
    assert "move_newest" not in episodes[0] and episodes[0]["action"] == episodes[0]["prior_action"]
    assert torch.equal(torch.tensor(episodes[-1]["action"]), actions[:, -1])


def test_trace_command_refuses_bad_requests_before_running_anything(tmp_path, capsys):
    from lerobot_predvla.cli.main import main as predvla_main

    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "trace.json").write_text(json.dumps({"eval_args": [], "episodes": [{"steps": [1]}] * 2}))
    cases = {
        ("--episode", "2", "--compare", str(earlier), str(tmp_path / "out"), "--policy.path=ckpt"):
            f"--episode 2: --compare {earlier.name} has 2 episodes",
        (str(tmp_path / "out"), "--env.type=predvla_libero"): "needs --policy.path",
        ("--compare", str(tmp_path), str(tmp_path / "out"), "--policy.path=ckpt"): f"--compare {tmp_path}",
    }
    for argv, message in cases.items():
        assert predvla_main(["trace", *argv]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
