"""Pre- and post-processing pipelines of the PredVLA policy."""

from typing import Any

import torch
from lerobot.processor import (
    AddBatchDimensionProcessorStep,
    DeviceProcessorStep,
    NormalizerProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    RenameObservationsProcessorStep,
    UnnormalizerProcessorStep,
)
from lerobot.processor.factory import make_policy_processor_pipelines

from .configuration_predvla import PredVLAConfig


def make_predvla_pre_post_processors(
    config: PredVLAConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Input: rename -> batch dim -> device -> normalise. Output: unnormalise actions -> cpu.

    The inputs are the cached front-end features: PCA outputs and raw proprioception pass through
    unchanged (identity, Section 3.1); actions are min-max scaled to the [-1, 1] range of the tanh
    component means and scaled back on the way out.
    """
    input_steps = [
        RenameObservationsProcessorStep(rename_map={}),
        AddBatchDimensionProcessorStep(),
        DeviceProcessorStep(device=config.device),
        NormalizerProcessorStep(
            features={**config.input_features, **config.output_features},
            norm_map=config.normalization_mapping,
            stats=dataset_stats,
        ),
    ]
    output_steps = [
        UnnormalizerProcessorStep(
            features=config.output_features, norm_map=config.normalization_mapping, stats=dataset_stats
        ),
        DeviceProcessorStep(device="cpu"),
    ]
    return make_policy_processor_pipelines(input_steps=input_steps, output_steps=output_steps)
