"""Discovery name for LeRobot's plugin loader (`register_third_party_plugins` imports `lerobot_policy_*`).

It only re-exports `lerobot_predvla`, whose import registers every policy type and the `predvla_libero` env.
"""

import lerobot_predvla
from lerobot_predvla import *  # noqa: F403

__all__ = lerobot_predvla.__all__
