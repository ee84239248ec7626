"""`predvla libero-demo --device`: the device reaches lerobot-train and lerobot-eval (stages faked, no simulator)."""

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
    assert predvla_main(["libero-demo", "--out", str(tmp_path), "--episodes", "2", *device_args]) == 0
    train = [c for c in commands if c[0].endswith("lerobot-train")]
    evals = [c for c in commands if c[0].endswith("lerobot-eval")]
    assert len(train) == 1 and len(evals) == 2
    for cmd in (*train, *evals):
        assert f"--policy.device={device}" in cmd
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["mean"] == {"error regression": 50.0, "open loop": 50.0}
