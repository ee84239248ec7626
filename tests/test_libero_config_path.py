"""LIBERO reads the config of this virtual environment, not whatever ~/.libero another checkout left."""

import os
import subprocess
import sys

from lerobot_predvla.sims.libero.config_path import (
    CONFIG_ENV,
    CONFIG_NAME,
    VENV_CONFIG_DIR,
    active_config,
    use_venv_config,
)


def test_the_venv_config_is_used_unless_the_user_chose_one(tmp_path, monkeypatch):
    monkeypatch.delenv(CONFIG_ENV, raising=False)
    assert not use_venv_config(tmp_path)  # nothing written there: hf-libero's default stays
    assert CONFIG_ENV not in os.environ and active_config() == tmp_path.home() / ".libero" / CONFIG_NAME
    (tmp_path / CONFIG_NAME).write_text("benchmark_root: /somewhere\n")
    assert use_venv_config(tmp_path)
    assert os.environ[CONFIG_ENV] == str(tmp_path) and active_config() == tmp_path / CONFIG_NAME
    monkeypatch.setenv(CONFIG_ENV, "/the/users/choice")
    assert not use_venv_config(tmp_path) and os.environ[CONFIG_ENV] == "/the/users/choice"


def test_importing_the_plugin_points_child_processes_at_the_venv_config(tmp_path):
    """A stale ~/.libero (HOME moved to an empty folder here) does not matter once `make libero` wrote the venv's."""
    env = {k: v for k, v in os.environ.items() if k != CONFIG_ENV} | {"HOME": str(tmp_path)}
    code = ("import os, lerobot_predvla, subprocess, sys; "
            f"print(subprocess.run([sys.executable, '-c', 'import os; print(os.environ.get(\"{CONFIG_ENV}\"))'], "
            "capture_output=True, text=True).stdout.strip())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    expected = str(VENV_CONFIG_DIR) if (VENV_CONFIG_DIR / CONFIG_NAME).is_file() else "None"
    assert out.stdout.strip().splitlines()[-1] == expected
