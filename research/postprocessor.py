"""A checkpoint's saved output pipeline, read back to turn a trace's normalised actions into the raw actions the
simulator runs (`er_correction`, `divergence`)."""

from pathlib import Path

from lerobot.processor import PolicyAction, PolicyProcessorPipeline
from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
from lerobot.utils.constants import POLICY_POSTPROCESSOR_DEFAULT_NAME

POSTPROCESSOR_FILE = f"{POLICY_POSTPROCESSOR_DEFAULT_NAME}.json"  # as LeRobot saves it beside the weights


def load_postprocessor(checkpoint: Path) -> PolicyProcessorPipeline[PolicyAction, PolicyAction]:
    """A checkpoint's saved output pipeline (`POSTPROCESSOR_FILE`): model actions in, raw actions out."""
    return PolicyProcessorPipeline.from_pretrained(
        checkpoint, POSTPROCESSOR_FILE, to_transition=policy_action_to_transition,
        to_output=transition_to_policy_action)
