"""Pre- and post-processing pipelines shared by every policy type of the plugin (same inputs: the cached features).

Each policy folder's `processor_<type>.py` gives LeRobot its `make_<type>_pre_post_processors` from this one.
"""

from typing import Any

import torch
from lerobot.processor import PolicyAction, PolicyProcessorPipeline
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines

from lerobot_predvla.columns import OBS_VISION_FEATURES
from lerobot_predvla.frontend.artefact import FrontendArtefact, FrontendArtefactError
from lerobot_predvla.frontend.processor_step import FrontendProcessorStep
from lerobot_predvla.policies.common.cached_features import CachedFeaturesConfig


def frontend_step(config: CachedFeaturesConfig) -> FrontendProcessorStep:
    """The frozen front end of `config.frontend_dir`, or a pass-through step for cached features only."""
    if config.frontend_dir is None:
        return FrontendProcessorStep()
    artefact = FrontendArtefact.load(config.frontend_dir)
    if artefact.oracle is not None:  # a diagnostic: the poses are one block of visual features, no camera is read
        if (artefact.language_dim, artefact.vision_dim) != (config.language_dim, config.vision_dim):
            raise FrontendArtefactError(
                f"{config.frontend_dir}: the oracle front end gives {artefact.vision_dim} visual and "
                f"{artefact.language_dim} language features, the policy was built for {config.vision_dim} and "
                f"{config.language_dim} (train it with --policy.vision_dim_per_camera={artefact.vision_dim})."
            )
    else:
        artefact.check_dims(
            config.language_dim, config.vision_dim_per_camera, list(artefact.cameras), config.frontend_dir
        )
        if len(artefact.cameras) != config.num_cameras:
            raise FrontendArtefactError(
                f"{config.frontend_dir}: the front end encodes {len(artefact.cameras)} cameras "
                f"{list(artefact.cameras)}, the policy was built for {config.num_cameras} (its "
                f"'{OBS_VISION_FEATURES}' features)."
            )
    return FrontendProcessorStep.from_artefact(artefact, refresh_interval=config.visual_refresh_interval)


def make_cached_features_pre_post_processors(
    config: CachedFeaturesConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """Input: rename -> batch dim -> device -> front end -> normalise. Output: unnormalise -> cpu.

    LeRobot's default steps (`make_default_policy_processor_steps`) with the front end inserted after the
    device step, so that its encoders run on the policy's device (`--policy.device`).
    The front-end step turns live environment observations into the cached features (training batches
    already have them) and carries the artefact of `config.frontend_dir` into the checkpoint. The inputs
    are the cached front-end features: PCA outputs and raw proprioception pass through
    unchanged (identity, Section 3.1); actions are min-max scaled to the [-1, 1] range of the tanh
    component means and scaled back on the way out.
    """
    s = make_default_policy_processor_steps(config, dataset_stats)
    return make_policy_processor_pipelines(
        input_steps=[s.rename_observations, s.add_batch_dim, s.to_device, frontend_step(config), s.normalize],
        output_steps=[s.unnormalize, s.to_cpu],
    )

