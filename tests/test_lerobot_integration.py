"""Every change the plugin makes to LeRobot is made by `lerobot_integration.install()` and documented."""

import inspect
import os
import subprocess
import sys
from pathlib import Path

from lerobot_predvla import lerobot_integration

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "lerobot_integration.md"
# Each replacement and environment variable: the function of lerobot_integration that makes it, and the LeRobot (or
# hf-libero) name it replaces.
CHANGES = {
    "point_libero_at_venv_config": ["LIBERO_CONFIG_PATH"],
    "make_env_pre_post_processors": ["make_env_pre_post_processors"],
    "eval_policy_all": ["eval_policy_all"],
    "install_lerobot_train_hooks": ["save_checkpoint", "update_last_checkpoint", "make_train_eval_datasets"],
}


def test_every_change_says_what_it_replaces_why_and_the_upstream_fix_and_the_page_lists_it():
    page = PAGE.read_text()
    for name, replaced in CHANGES.items():
        doc = inspect.getdoc(getattr(lerobot_integration, name))
        assert "Replaces" in doc and "Why" in doc and "Upstream" in doc, name
        assert all(f"`{r}`" in doc and f"`{r}" in page for r in replaced), name


def test_importing_the_plugin_installs_every_change_once_and_loads_no_simulator():
    code = """
import os, sys
import lerobot.envs, lerobot.envs.factory
from lerobot.scripts import lerobot_eval
import lerobot_predvla
from lerobot_predvla import lerobot_integration as li
from lerobot_predvla.sims.libero.config_path import CONFIG_NAME, VENV_CONFIG_DIR
li.install()  # a second call changes nothing
assert lerobot.envs.make_env_pre_post_processors is li.make_env_pre_post_processors
assert lerobot.envs.factory.make_env_pre_post_processors is li.make_env_pre_post_processors
assert lerobot_eval.eval_policy_all is li.eval_policy_all
assert li._lerobot_eval_policy_all.__module__ == "lerobot.scripts.lerobot_eval"
assert "libero.libero" not in sys.modules
expected = str(VENV_CONFIG_DIR) if (VENV_CONFIG_DIR / CONFIG_NAME).is_file() else None
assert os.environ.get("LIBERO_CONFIG_PATH") == expected, os.environ.get("LIBERO_CONFIG_PATH")
"""
    env = {k: v for k, v in os.environ.items() if k != "LIBERO_CONFIG_PATH"}
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]


def test_the_predvla_command_sets_mujoco_gl_only_once_it_loads_the_simulator():
    """Every `predvla` subcommand's module imported and its parser built: no simulator loaded and no `MUJOCO_GL`
    set (only loading LIBERO sets it, sims/libero/env.py), so what a command starts inherits the user's environment."""
    code = """
import os, sys
from lerobot_predvla.cli.main import build_parser
build_parser()
assert "libero.libero" not in sys.modules
assert "MUJOCO_GL" not in os.environ, os.environ["MUJOCO_GL"]
"""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    result = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
