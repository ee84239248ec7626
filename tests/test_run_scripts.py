"""The long runs' scripts under results/ (`results/chain.sh` and the scripts that source it), run with a recording
`predvla` on PATH in a copy of the paths they read: the commands in their order, STOP_AT honoured and passed on,
a bad STOP_AT refused, and a failing step ending the chain."""

import os
import shutil
import stat
import subprocess
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
SCRIPTS = {  # script -> number of `predvla` calls of a whole run
    "results/demonstrations/teleop_full/run.sh": 13,
    "results/demonstrations/teleop_placed_full/run.sh": 19,
    "results/demonstrations/scripted_full/run.sh": 16,
    "results/libero_four_suites/run.sh": 34,
    "results/demonstrations/blind_replay_full/run.sh": 7,
}
SWEEP_SCRIPTS = [s for s in SCRIPTS if "blind_replay" not in s]


def run_script(tmp_path: Path, script: str, stop_at: str | None = None, exit_code: int = 0):
    """Runs `script` from a copy of the repository's run files; returns (process, list of recorded calls)."""
    root = tmp_path / "repo"
    for rel in [*SCRIPTS, "results/chain.sh"]:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, root / rel)
    (root / "results/demonstrations/scripted_full/runs/train").mkdir(parents=True, exist_ok=True)
    calls = tmp_path / "calls"
    fake = tmp_path / "bin" / "predvla"
    fake.parent.mkdir(exist_ok=True)
    fake.write_text(f'#!/bin/bash\necho "$MUJOCO_GL $*" >> {calls}\nexit {exit_code}\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    env = {k: v for k, v in os.environ.items() if k not in ("STOP_AT", "MUJOCO_GL")}
    env["PATH"] = f"{fake.parent}:{env['PATH']}"
    if stop_at is not None:
        env["STOP_AT"] = stop_at
    proc = subprocess.run(["bash", script], cwd=root, env=env, capture_output=True, text=True, timeout=60)
    return proc, calls.read_text().splitlines() if calls.exists() else []


@pytest.mark.parametrize("script", list(SCRIPTS))
def test_a_whole_run_makes_every_call_in_the_offscreen_environment(tmp_path, script):
    proc, calls = run_script(tmp_path, script)
    assert proc.returncode == 0, proc.stderr
    assert len(calls) == SCRIPTS[script]
    assert all(c.startswith("egl ") for c in calls)
    assert not any("--stop-at" in c for c in calls)


@pytest.mark.parametrize("script", SWEEP_SCRIPTS)
def test_stop_at_is_passed_to_every_sweep_as_an_iso_time(tmp_path, script):
    proc, calls = run_script(tmp_path, script, stop_at="23:59 tomorrow")
    assert proc.returncode == 0, proc.stderr
    assert len(calls) == SCRIPTS[script]
    stop = subprocess.run(["date", "-d", "23:59 tomorrow", "-Iminutes"], capture_output=True, text=True).stdout.strip()
    assert all(c.endswith(f"--stop-at {stop}") for c in calls)


@pytest.mark.parametrize("script", list(SCRIPTS))
def test_a_past_stop_at_starts_nothing(tmp_path, script):
    proc, calls = run_script(tmp_path, script, stop_at="1 minute ago")
    assert proc.returncode == 0, proc.stderr
    assert calls == []


def test_a_stop_at_that_is_not_a_date_is_refused(tmp_path):
    proc, calls = run_script(tmp_path, "results/demonstrations/teleop_full/run.sh", stop_at="tomorrow-ish")
    assert proc.returncode == 2
    assert "STOP_AT: not a date: tomorrow-ish" in proc.stderr
    assert calls == []


@pytest.mark.parametrize("script", SWEEP_SCRIPTS)
def test_the_chain_ends_at_the_first_step_that_fails(tmp_path, script):
    proc, calls = run_script(tmp_path, script, exit_code=3)
    assert proc.returncode == 3
    assert len(calls) == 1
    progress = next((tmp_path / "repo/results").rglob("*.progress")).read_text()
    assert progress.splitlines()[-1].endswith("rc=3")


@pytest.mark.parametrize("script", SWEEP_SCRIPTS)
def test_every_config_and_suite_a_script_names_is_in_its_sweep_file(tmp_path, script):
    _, calls = run_script(tmp_path, script)
    for call in calls:
        args = call.split()[2:]  # after "$MUJOCO_GL sweep"
        sweep = yaml.safe_load((REPO / args[0]).read_text())
        names = {c["name"] for c in sweep["configs"]}
        for flag, known in (("--configs", names), ("--suites", set(sweep["suites"]))):
            if flag in args:
                assert set(args[args.index(flag) + 1].split(",")) <= known, (script, call)
