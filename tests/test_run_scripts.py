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


def run_script(tmp_path: Path, script: str, stop_at: str | None = None, exit_code: int = 0, avx512: bool = True,
               env_extra: dict | None = None, cwd: Path | None = None):
    """Runs `script` from a copy of the repository's run files on a processor with AVX-512 or without (a fake
    CHAIN_CPUINFO); returns (process, list of recorded calls: MUJOCO_GL, OPENBLAS_CORETYPE, arguments)."""
    root = tmp_path / "repo"
    for rel in [*SCRIPTS, "results/chain.sh"]:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / rel, root / rel)
    (root / "results/demonstrations/scripted_full/runs/train").mkdir(parents=True, exist_ok=True)
    calls = tmp_path / "calls"
    fake = tmp_path / "bin" / "predvla"
    fake.parent.mkdir(exist_ok=True)
    fake.write_text(f'#!/bin/bash\necho "$MUJOCO_GL ${{OPENBLAS_CORETYPE:-none}} $*" >> {calls}\nexit {exit_code}\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(f"flags\t\t: fpu sse4_2 avx2 fma{' avx512f avx512bw' if avx512 else ''}\n")
    env = {k: v for k, v in os.environ.items() if k not in ("STOP_AT", "MUJOCO_GL", "ALLOW_OTHER_KERNELS")}
    env.update({"PATH": f"{fake.parent}:{env['PATH']}", "CHAIN_CPUINFO": str(cpuinfo), **(env_extra or {})})
    if stop_at is not None:
        env["STOP_AT"] = stop_at
    proc = subprocess.run(["bash", str(root / script) if cwd else script], cwd=cwd or root, env=env,
                          capture_output=True, text=True, timeout=60)
    return proc, calls.read_text().splitlines() if calls.exists() else []


@pytest.mark.parametrize("script", list(SCRIPTS))
def test_a_whole_run_makes_every_call_in_the_offscreen_environment(tmp_path, script):
    proc, calls = run_script(tmp_path, script)
    assert proc.returncode == 0, proc.stderr
    assert len(calls) == SCRIPTS[script]
    assert all(c.startswith("egl SkylakeX ") for c in calls)
    assert not any("--stop-at" in c for c in calls)


@pytest.mark.parametrize("script", SWEEP_SCRIPTS)
def test_stop_at_is_passed_to_every_sweep_as_an_iso_time(tmp_path, script):
    proc, calls = run_script(tmp_path, script, stop_at="23:59 tomorrow")
    assert proc.returncode == 0, proc.stderr
    assert len(calls) == SCRIPTS[script]
    stop = subprocess.run(["date", "-d", "23:59 tomorrow", "-Iseconds"], capture_output=True, text=True).stdout.strip()
    assert all(c.endswith(f"--stop-at {stop}") for c in calls)


def test_a_bare_time_already_past_today_means_the_next_one(tmp_path):
    """As `predvla sweep --stop-at HH:MM` reads it: 00:00 given during the day stops at the coming midnight."""
    proc, calls = run_script(tmp_path, "results/demonstrations/teleop_full/run.sh", stop_at="00:00")
    assert proc.returncode == 0, proc.stderr
    stop = subprocess.run(["date", "-d", "00:00 tomorrow", "-Iseconds"], capture_output=True, text=True).stdout.strip()
    assert len(calls) == 13 and all(c.endswith(f"--stop-at {stop}") for c in calls)


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
        args = call.split()[3:]  # after "$MUJOCO_GL $OPENBLAS_CORETYPE sweep"
        sweep = yaml.safe_load((REPO / args[0]).read_text())
        names = {c["name"] for c in sweep["configs"]}
        for flag, known in (("--configs", names), ("--suites", set(sweep["suites"]))):
            if flag in args:
                assert set(args[args.index(flag) + 1].split(",")) <= known, (script, call)


def test_a_script_run_outside_the_repository_root_stops_before_any_call(tmp_path):
    proc, calls = run_script(tmp_path, "results/demonstrations/blind_replay_full/run.sh", cwd=tmp_path)
    assert proc.returncode == 2 and "results/chain.sh" in proc.stderr
    assert calls == []


@pytest.mark.parametrize("allow", [False, True])
def test_without_avx512_no_step_remakes_a_committed_dataset_unless_allowed(tmp_path, allow):
    """Without AVX-512 the SkylakeX kernels a caller pinned are dropped (they would stop every process), the
    evaluations run, and the step whose data stage would remake D2 is not started unless ALLOW_OTHER_KERNELS=1."""
    extra = {"OPENBLAS_CORETYPE": "SkylakeX", **({"ALLOW_OTHER_KERNELS": "1"} if allow else {})}
    proc, calls = run_script(tmp_path, "results/demonstrations/teleop_full/run.sh", avx512=False, env_extra=extra)
    assert all(c.startswith("egl none ") for c in calls)
    if allow:
        assert proc.returncode == 0 and len(calls) == 13
    else:
        assert proc.returncode == 3 and len(calls) == 9 and "--train-only" not in " ".join(calls)
        assert "B2_train not started: it would make outputs/libero_object_teleop/dataset_features" in proc.stderr


def test_without_avx512_an_existing_dataset_is_used_as_it_is(tmp_path):
    (tmp_path / "repo/outputs/libero_object_teleop_placed/dataset_features").mkdir(parents=True)
    proc, calls = run_script(tmp_path, "results/demonstrations/teleop_placed_full/run.sh", avx512=False)
    assert proc.returncode == 0 and len(calls) == 19
