"""The error-regression tracer (`predvla trace`) reads the steps of `ErrorRegression` and changes none of them."""

import dataclasses
import json

import torch

from benchmarks.bench_core import control_stream, randomised_model
from lerobot_predvla import PredVLAConfig
from lerobot_predvla.policies.predvla.error_regression import ErrorRegression
from lerobot_predvla.policies.predvla.trace import TraceRecorder, correlations, plot_corrections


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
    # The errors the step observed: eps_v, eps_q (Eq. 7) of the newest step, the window regenerated from the
    # posteriors before and after its iterations.
    errors = {}
    for key, c_q in (("error_before", before), ("error_after", torch.stack(er.posteriors))):
        traj = model.rollout(er.start_state, er.lang_term, c_q)
        v_hat = model.v_head(traj.d[1])[-1]
        eps_v, eps_q = (obs[4][0] - v_hat).pow(2).mean(-1), (obs[4][1] - traj.q_hat[-1]).pow(2).mean(-1)
        errors[key] = torch.stack([eps_v, eps_q], -1)
    episodes = recorder.episodes()
    assert len(episodes) == 2 and episodes[0]["steps"] == [1, 2, 3, 4, 5]
    for i, episode in enumerate(episodes):
        assert torch.allclose(torch.tensor(episode["move_newest"][4]), change[i].float(), atol=1e-6)
        assert len(episode["move_window"]) == 5 and len(episode["move_window"][0]) == 4
        for key, value in errors.items():
            assert torch.allclose(torch.tensor(episode[key][4]), value[i].float(), rtol=1e-6)
        assert episode["error_before"][4] != episode["error_after"][4]  # the iterations moved the prediction
        assert len(episode["vision_weight"]) == 5


def test_correlations_rank_each_module_move_against_the_observed_error(tmp_path):
    # Two episodes, 4 steps: T's move rises with eps_v, V's falls with it, A_top is constant (undefined), A_bottom
    # follows eps_q; step 3 of episode 0 has a stale frame, so its eps_v is left out.
    def episode(eps_v, eps_q, weights):
        return {"steps": [1, 2, 3, 4],
                "error_before": [[v, q] for v, q in zip(eps_v, eps_q, strict=True)],
                "error_after": [[v / 2, q / 4] for v, q in zip(eps_v, eps_q, strict=True)],
                "move_newest": [[v, 1 / v, 0.5, q] for v, q in zip(eps_v, eps_q, strict=True)],
                "vision_weight": weights}
    episodes = [episode([1.0, 2.0, 9.0, 4.0], [0.1, 0.3, 0.2, 0.4], [1, 1, 0, 1]),
                episode([5.0, 6.0, 7.0, 8.0], [0.5, 0.7, 0.6, 0.8], [1, 1, 1, 1])]
    got = correlations(episodes)
    assert got["vision"] == {"T": 1.0, "V": -1.0, "A_top": None, "A_bottom": got["vision"]["A_bottom"]}
    assert got["proprio"]["A_bottom"] == 1.0
    assert got["median_after_over_before"] == {"vision": 0.5, "proprio": 0.25}
    assert correlations([{"steps": [1], "action": [[0.0]]}])["vision"]["T"] is None  # open loop: nothing to rank
    plot_corrections(episodes, [True, False], tmp_path / "c.png", "test")
    assert (tmp_path / "c.png").stat().st_size > 0


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
