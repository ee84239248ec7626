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

from .configuration_predvla import OBS_VISION_FEATURES, PredVLAConfig
from .frontend.artefact import FrontendArtefact, FrontendArtefactError
from .frontend.processor_step import FrontendProcessorStep


def frontend_step(config: PredVLAConfig) -> FrontendProcessorStep:
    """The frozen front end of `config.frontend_dir`, or a pass-through step for cached features only."""
    if config.frontend_dir is None:
        return FrontendProcessorStep()
    artefact = FrontendArtefact.load(config.frontend_dir)
    artefact.check_dims(
        config.language_dim, config.vision_dim_per_camera, list(artefact.cameras), config.frontend_dir
    )
    if len(artefact.cameras) != config.num_cameras:
        raise FrontendArtefactError(
            f"{config.frontend_dir}: the front end encodes {len(artefact.cameras)} cameras {list(artefact.cameras)}, "
            f"the policy was built for {config.num_cameras} (its '{OBS_VISION_FEATURES}' features)."
        )
    return FrontendProcessorStep.from_artefact(artefact)


def make_predvla_pre_post_processors(
    config: PredVLAConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Input: rename -> batch dim -> front end -> device -> normalise. Output: unnormalise -> cpu.

    The front-end step turns live environment observations into the cached features (training batches
    already have them) and carries the artefact of `config.frontend_dir` into the checkpoint. The inputs
    are the cached front-end features: PCA outputs and raw proprioception pass through
    unchanged (identity, Section 3.1); actions are min-max scaled to the [-1, 1] range of the tanh
    component means and scaled back on the way out.
    """
    input_steps = [
        RenameObservationsProcessorStep(rename_map={}),
        AddBatchDimensionProcessorStep(),
        frontend_step(config),
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
