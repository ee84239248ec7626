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
    assert er["er_eps_v"] > 0 and er["er_eps_q"] > 0  # finite: the visual error of the refresh steps
    for name in ("open_loop_vs_demos", "language_swap", "prior_posterior_gap", "errors_over_episode",
                 "training_curves"):
        assert (out / f"{name}.png").stat().st_size > 1000


def test_inspect_names_a_path_without_checkpoint(tmp_path, capsys):
    assert main(["inspect", str(tmp_path)]) == 2
    assert str(tmp_path) in capsys.readouterr().err
