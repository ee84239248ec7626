"""A policy config's recipe: the fields that change what is computed, and how a config departs from its defaults.

Used by the model card (hub/card.py), the headline table (report/headline.py) and the sweep runner.
"""

from dataclasses import MISSING, dataclass, fields

from lerobot.configs.policies import PreTrainedConfig

# Policy fields that say where or how fast a run computes, not what it computes.
NOT_RECIPE = frozenset({"type", "push_to_hub", "device", "recurrence_backend", "use_amp", "repo_id"})
# PredVLA defaults that Table 2 does not give a value for (the open choices of docs/paper.md).
UNSTATED_IN_TABLE2 = {"grad_clip_norm"}


@dataclass(frozen=True)
class Departure:
    """One way a run departs from the paper: what it does (`label`, e.g. `lambda_q = 100`) and what it departs from
    (`reference`, e.g. `Table 2: 1`)."""

    label: str
    reference: str

    def __str__(self) -> str:
        return f"{self.label} ({self.reference})"


def format_number(value) -> str:
    """A number as a reader writes it (`30,000`, `0.05`); anything else as its string."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f"{int(value):,}" if value.is_integer() else f"{value:g}"


def differs(value, default) -> bool:
    if isinstance(value, list | tuple) or isinstance(default, list | tuple):
        return not (isinstance(value, list | tuple) and isinstance(default, list | tuple) and len(value) == len(default)
                    and not any(differs(v, d) for v, d in zip(value, default, strict=True)))
    try:
        return float(value) != float(default)
    except (TypeError, ValueError):
        return str(value) != str(default)


def config_defaults(policy_type: str) -> dict:
    """The default of every field of a policy type's config class (PredVLA's are Table 2's). The package's import
    registers every config class of the plugin before any of its modules runs."""
    config_cls = PreTrainedConfig.get_choice_class(policy_type)
    return {f.name: f.default for f in fields(config_cls) if f.default is not MISSING}


def config_departures(values: dict) -> list[Departure]:
    """`field = value` against `Table 2: default` for every recipe field of a policy config (`config.json`, or
    `--policy.*` values with `type`) that differs from its config class's default (PredVLA's are Table 2's, but for
    the values Table 2 does not give)."""
    defaults = config_defaults(values["type"])
    paper = values["type"] == "predvla"

    def reference(k: str) -> str:
        if paper and k in UNSTATED_IN_TABLE2:
            return f"default: {format_number(defaults[k])}; Table 2 gives no value"
        return f"{'Table 2' if paper else 'default'}: {format_number(defaults[k])}"

    return [Departure(f"{k} = {format_number(v)}", reference(k))
            for k, v in sorted(values.items())
            if k in defaults and k not in NOT_RECIPE and differs(v, defaults[k])]
