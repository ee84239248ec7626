"""`predvla demo libero --device`: the device reaches lerobot-train and lerobot-eval (stages faked, no simulator)."""

import json
from pathlib import Path

import pytest

from lerobot_predvla.cli import libero_demo
from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.utils.checkpoints import last_pretrained


def fake_stages(commands: list[list[str]]):
    """Record each stage's command; lerobot-train leaves a checkpoint, lerobot-eval an eval_info.json."""

    def run(stage: str, cmd: list[str]) -> None:
        commands.append(cmd)
        out = next((Path(a.split("=", 1)[1]) for a in cmd if a.startswith("--output_dir=")), None)
        if cmd[0].endswith("lerobot-train"):
            last_pretrained(out).mkdir(parents=True)
        elif cmd[0].endswith("lerobot-eval"):
            out.mkdir(parents=True)
            info = {"per_task": [{"task_id": 0, "metrics": {"successes": [True, False]}}]}
            (out / "eval_info.json").write_text(json.dumps(info))

    return run


@pytest.mark.parametrize("device_args, device", [([], "cpu"), (["--device", "cuda"], "cuda")])
def test_libero_demo_passes_the_device_to_lerobot(tmp_path, monkeypatch, device_args, device):
    commands: list[list[str]] = []
    monkeypatch.setattr(libero_demo, "_run", fake_stages(commands))
    args = ["demo", "libero", "--out", str(tmp_path), "--episodes", "2", "--suite-checkpoint", "none"]
    assert predvla_main([*args, *device_args]) == 0
    train = [c for c in commands if c[0].endswith("lerobot-train")]
    evals = [c for c in commands if c[0].endswith("lerobot-eval")]
    assert len(train) == 1 and len(evals) == 2
    for cmd in (*train, *evals):
        assert f"--policy.device={device}" in cmd
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["mean"] == {"error regression": 50.0, "open loop": 50.0}


def test_libero_demo_evaluates_the_suite_checkpoint_on_two_tasks(tmp_path, monkeypatch):
    """Stage 6: the shipped suite checkpoint, both modes, on its own tasks; open loop renders only at reset."""
    suite = tmp_path / "suite_ckpt"
    suite.mkdir()
    (suite / "config.json").write_text("{}")
    commands: list[list[str]] = []
    monkeypatch.setattr(libero_demo, "_run", fake_stages(commands))
    out = tmp_path / "demo"
    assert predvla_main(["demo", "libero", "--out", str(out), "--episodes", "2", "--suite-checkpoint", str(suite),
                         "--suite-tasks", "0,7", "--suite-episodes", "3"]) == 0
    evals = [c for c in commands if c[0].endswith("lerobot-eval")]
    assert len(evals) == 4
    on_suite = [c for c in evals if f"--policy.path={suite}" in c]
    assert len(on_suite) == 2
    for cmd in on_suite:
        assert "--env.task_ids=[0,7]" in cmd and "--eval.n_episodes=3" in cmd
    open_loop = [c for c in evals if "--policy.er_iterations=0" in c]
    assert all("--env.render_interval=100000" in c for c in open_loop) and len(open_loop) == 2
    results = json.loads((out / "results.json").read_text())
    assert results["suite_checkpoint"]["path"] == str(suite)
    assert results["suite_checkpoint"]["mean"] == {"error regression": 50.0, "open loop": 50.0}
    assert (out / "success_suite_checkpoint.png").is_file()
    # A missing checkpoint is said, and the stage skipped; the demo's own results stand.
    commands.clear()
    other = tmp_path / "demo2"
    assert predvla_main(["demo", "libero", "--out", str(other), "--suite-checkpoint", str(tmp_path / "nowhere")]) == 0
    assert "suite_checkpoint" not in json.loads((other / "results.json").read_text())
