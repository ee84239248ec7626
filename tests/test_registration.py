"""One registration point: `import lerobot_predvla` registers every policy type and env type of the plugin."""

import json
import subprocess
import sys

import pytest

import lerobot_policy_predvla
import lerobot_predvla

POLICY_TYPES = {"predvla", "predvla_bc_transformer", "predvla_bc_rnn", "predvla_ladder"}


def registered_around(statement: str) -> tuple[dict, dict]:
    """Policy and env types LeRobot knows in a fresh interpreter before and after running `statement`."""
    known = (
        "json.dumps({'policies': sorted(PreTrainedConfig.get_known_choices()),"
        " 'envs': sorted(EnvConfig.get_known_choices())})"
    )
    code = (
        "import json\n"
        "from lerobot.configs import PreTrainedConfig\n"
        "from lerobot.envs.configs import EnvConfig\n"
        f"print({known})\n"
        f"{statement}\n"
        f"print({known})\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    before, after = out.strip().splitlines()[-2:]
    return json.loads(before), json.loads(after)


@pytest.mark.parametrize("statement", [
    "import lerobot_predvla",
    "import lerobot_policy_predvla",
    # What lerobot-train and lerobot-eval do: import every installed `lerobot_policy_*` distribution.
    "from lerobot.utils.import_utils import register_third_party_plugins; register_third_party_plugins()",
])
def test_one_import_registers_every_policy_and_env_type(statement):
    before, after = registered_around(statement)
    assert not POLICY_TYPES & set(before["policies"]) and "predvla_libero" not in before["envs"]
    assert POLICY_TYPES <= set(after["policies"])
    assert "predvla_libero" in after["envs"]
    assert set(lerobot_predvla.POLICY_TYPES) == POLICY_TYPES


def test_the_shim_only_re_exports():
    assert lerobot_policy_predvla.__all__ == lerobot_predvla.__all__
    for name in lerobot_predvla.__all__:
        assert getattr(lerobot_policy_predvla, name) is getattr(lerobot_predvla, name)
    public = {n for n in vars(lerobot_policy_predvla) if not n.startswith("_")}
    assert public == set(lerobot_predvla.__all__) | {"lerobot_predvla"}


@pytest.mark.parametrize("policy_type", sorted(POLICY_TYPES))
def test_lerobot_resolves_policy_and_processors_by_name(policy_type):
    """LeRobot's factory finds `XPolicy` in `modeling_*` and `make_x_pre_post_processors` in `processor_*`
    beside the registered `configuration_*` module."""
    from lerobot.configs import PreTrainedConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    config = PreTrainedConfig.get_choice_class(policy_type)(device="cpu")
    config.validate_features()
    policy_cls = get_policy_class(policy_type)
    assert policy_cls.config_class is type(config) and policy_cls.name == policy_type
    assert policy_cls.__module__ == type(config).__module__.replace("configuration_", "modeling_")
    pre, post = make_pre_post_processors(config, dataset_stats=None)
    assert pre.name == "policy_preprocessor" and post.name == "policy_postprocessor"
