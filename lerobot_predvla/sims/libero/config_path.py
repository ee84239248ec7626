"""Which LIBERO config this environment's processes read.

hf-libero reads `$LIBERO_CONFIG_PATH/config.yaml`, by default `~/.libero/config.yaml`: one file per user, which
the last `make libero` of any checkout points at its own virtual environment's assets. Once that checkout's
environment is gone, every other checkout's simulator fails at import. `make libero` therefore also writes the
config inside this environment (`VENV_CONFIG_DIR`), and importing the plugin points `LIBERO_CONFIG_PATH` there
when the user has not set it (child processes inherit it).
"""

import os
import sys
from pathlib import Path

CONFIG_ENV = "LIBERO_CONFIG_PATH"
CONFIG_NAME = "config.yaml"
VENV_CONFIG_DIR = Path(sys.prefix) / "libero_config"


def active_config() -> Path:
    """The config hf-libero reads now: `$LIBERO_CONFIG_PATH/config.yaml`, by default `~/.libero/config.yaml`."""
    return Path(os.environ.get(CONFIG_ENV, Path.home() / ".libero")) / CONFIG_NAME


def use_venv_config(directory: Path = VENV_CONFIG_DIR) -> bool:
    """Point LIBERO at `directory`'s config unless LIBERO_CONFIG_PATH is set; True when it did."""
    if CONFIG_ENV in os.environ or not (directory / CONFIG_NAME).is_file():
        return False
    os.environ[CONFIG_ENV] = str(directory)
    return True
