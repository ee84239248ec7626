"""LeRobot env types of the plugin (`--env.type=predvla_libero`).

Importing it points LIBERO at the config `make libero` wrote inside this virtual environment, before anything
imports the simulator (lerobot_predvla/libero/config_path.py says why).
"""

from lerobot_predvla.libero.config_path import use_venv_config

use_venv_config()
