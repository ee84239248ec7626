"""One folder per policy type, as LeRobot lays out its own: `configuration_*`, `modeling_*`, `processor_*`."""

# `--policy.type` of every policy of the plugin, in the order the paper introduces them.
POLICY_TYPES = ("predvla", "predvla_bc_transformer", "predvla_bc_rnn", "predvla_ladder")
