"""The frozen front end as a LeRobot processor step: live observations -> PredVLA's cached features."""

from dataclasses import InitVar, dataclass, field
from typing import Any

import numpy as np
import torch
from lerobot.configs.types import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.lerobot_types import EnvTransition, TransitionKey
from lerobot.processor import ProcessorStep, ProcessorStepRegistry
from lerobot.utils.constants import OBS_ENV_STATE, OBS_IMAGES

from lerobot_predvla.columns import OBS_IMAGE_FRESH, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.frontend.artefact import FrontendArtefact, FrontendArtefactError
from lerobot_predvla.frontend.frozen import FrozenFrontend
from lerobot_predvla.frontend.oracle import OracleStandardisation
from lerobot_predvla.utils.threads import acting_threads

CAMERA_PREFIX = f"{OBS_IMAGES}."


@ProcessorStepRegistry.register("predvla_frontend_processor")
@dataclass
class FrontendProcessorStep(ProcessorStep):
    """Encode camera images and the task string with the checkpoint's own frozen front end.

    Training batches already carry the converter's cached columns and pass through untouched. From an
    environment (`lerobot-eval`) or a robot (`lerobot-rollout`), images go through the same preprocessing,
    ResNet18 and PCA bases as in `predvla convert`, and the task string through all-MiniLM-L6-v2 and its PCA
    basis. Images are encoded only on refresh ticks: where the environment marks them fresh
    (`observation.image_fresh`, with `--env.type=predvla_libero`), else every `refresh_interval`-th call since
    `reset()` (the policy's `visual_refresh_interval`, the ticks whose frame its error regression reads); in
    between the last visual features are repeated, which the policy masks out of the free energy (Eq. 9).

    The encoders run on the device of the incoming images: after the pipeline's device step, the policy's
    (`--policy.device`), whatever device the checkpoint was trained on.

    The first observation after `reset()` that carries camera images must carry every camera the front end
    was fitted on, under its trained name; otherwise the step stops with an error listing the trained and the
    received names (a misnamed or unplugged camera). Later, a camera frame that is missing or holds
    non-finite pixels cannot be encoded: that environment's visual features become NaN for the step, which
    the policy treats as an unavailable observation (masked out of the free energy, `on_bad_observation`);
    the other environments are encoded as usual. An empty task is an error naming `--task`.

    A policy trained with the oracle front end (`predvla convert --oracle`, a diagnostic) takes its visual
    features from the simulator's object poses relative to the gripper (`observation.environment_state`, from
    `--env.type=predvla_libero --env.oracle=true`), standardised as in the converter, instead of the cameras.

    The artefact's JSON description is this step's config and its PCA arrays are its state, so the front
    end is saved with every checkpoint (`policy_preprocessor*.json/.safetensors`) and pushed with it.

    Args:
        artefact: JSON description of the front-end artefact (`frontend.json`); None for a policy trained
            on data without one (it can then only consume cached features).
        refresh_interval: Encode images every this many calls since `reset()` when the environment does not
            mark fresh frames (checkpoints saved before it was recorded: 1, every call).
        device: Ignored; older checkpoints recorded the encoders' device here (they now follow the images').
    """

    artefact: dict | None = None
    refresh_interval: int = 1
    device: InitVar[str | None] = None
    _arrays: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False)
    _frontend: FrozenFrontend | None = field(default=None, init=False, repr=False)
    _vision: torch.Tensor | None = field(default=None, init=False, repr=False)
    _language: dict[str, torch.Tensor] = field(default_factory=dict, init=False, repr=False)
    _tick: int = field(default=0, init=False, repr=False)

    def __post_init__(self, device: str | None) -> None:
        if self.refresh_interval < 1:
            raise ValueError(f"predvla_frontend_processor: refresh_interval must be >= 1, got {self.refresh_interval}.")

    @classmethod
    def from_artefact(cls, artefact: FrontendArtefact, refresh_interval: int = 1) -> "FrontendProcessorStep":
        step = cls(artefact=artefact.metadata(), refresh_interval=refresh_interval)
        step._arrays = artefact.tensors()
        return step

    def get_config(self) -> dict[str, Any]:
        return {"artefact": self.artefact, "refresh_interval": self.refresh_interval}

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {key: torch.from_numpy(np.ascontiguousarray(a)) for key, a in self._arrays.items()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self._arrays = {key: t.cpu().numpy() for key, t in state.items()}
        self._frontend = None

    def reset(self) -> None:
        self._vision = None
        self._tick = 0

    def frontend(self, device: torch.device | str = "cpu") -> FrozenFrontend:
        """The encoders on `device`, built on first use (seconds) and checked against the artefact's fingerprints."""
        if self._frontend is None or torch.device(self._frontend.device) != torch.device(device):
            if self.artefact is None:
                raise FrontendArtefactError(
                    "This PredVLA checkpoint has no front-end artefact, so it can only consume the cached "
                    f"'{OBS_VISION_FEATURES}' / '{OBS_LANGUAGE_FEATURES}' columns. Train on a dataset written by "
                    "`predvla convert` (it carries meta/predvla_frontend) or pass --policy.frontend_dir."
                )
            artefact = FrontendArtefact.from_metadata(self.artefact, self._arrays, where="policy_preprocessor")
            self._frontend = FrozenFrontend(artefact, device=str(device))
        return self._frontend

    def __call__(self, transition: EnvTransition) -> EnvTransition:
        observation = transition.get(TransitionKey.OBSERVATION)
        if observation is None or OBS_VISION_FEATURES in observation:
            return transition  # training batch: cached columns from the converter
        tasks = (transition.get(TransitionKey.COMPLEMENTARY_DATA) or {}).get("task")
        tasks = [tasks] if tasks is None or isinstance(tasks, str) else list(tasks)
        if not all(isinstance(t, str) and t.strip() for t in tasks):
            raise ValueError(
                f"PredVLA's front end needs the task instruction, got {tasks}: pass it with lerobot-rollout's "
                "--task='...' (or --dataset.single_task), as worded in the training dataset."
            )
        device = self._device(observation)
        with acting_threads(device):  # one thread on the CPU unless OMP_NUM_THREADS is set (utils/threads.py)
            return self._encode(transition, observation, tasks, device)

    def _encode(self, transition: EnvTransition, observation: dict, tasks: list[str],
                device: torch.device) -> EnvTransition:
        frontend = self.frontend(device)
        oracle = frontend.artefact.oracle
        fresh = observation.get(OBS_IMAGE_FRESH)
        if self._vision is None and oracle is None:
            self._check_cameras(observation)
        refresh = self._tick % self.refresh_interval == 0 if fresh is None else bool(torch.as_tensor(fresh).any())
        if self._vision is None or refresh:
            if oracle is None:
                self._vision = self._encode_frame(frontend, observation, len(tasks)).to(device)
            else:
                self._vision = self._oracle_frame(oracle, observation).to(device)
        self._tick += 1
        for text in set(tasks) - set(self._language):
            self._language[text] = frontend.encode_instructions([text])[0]
        new_observation = dict(observation)
        new_observation[OBS_VISION_FEATURES] = self._vision
        new_observation[OBS_LANGUAGE_FEATURES] = torch.stack([self._language[t] for t in tasks]).to(device)
        new_transition = dict(transition)
        new_transition[TransitionKey.OBSERVATION] = new_observation
        return new_transition

    def _device(self, observation: dict) -> torch.device:
        """Where the observation's images are (the policy's device after the pipeline's device step)."""
        images = [x for k, x in observation.items() if k.startswith(CAMERA_PREFIX) and isinstance(x, torch.Tensor)]
        return images[0].device if images else torch.device("cpu")

    def _check_cameras(self, observation: dict) -> None:
        """At an episode's first observation with images: every trained camera under its trained name."""
        trained = list(self.artefact["vision"]["cameras"])
        received = sorted(k for k in observation if k.startswith(CAMERA_PREFIX))
        missing = [key for key in trained if key not in observation]
        if received and missing:
            raise KeyError(
                f"PredVLA was trained on the cameras {trained}; the first observation has {received} (missing "
                f"{missing}). Name the robot's cameras as in the training dataset (e.g. lerobot-rollout "
                "--robot.cameras='{front: {...}}' or --rename_map), or in LIBERO evaluate with "
                "--env.type=predvla_libero."
            )

    def _encode_frame(self, frontend: FrozenFrontend, observation: dict, batch_size: int) -> torch.Tensor:
        """Visual features (batch, vision_dim); NaN rows where a camera frame is missing or non-finite."""
        cameras = list(frontend.artefact.cameras)
        present = {key: torch.as_tensor(observation[key]) for key in cameras if key in observation}
        others = sorted(k for k in observation if k.startswith(CAMERA_PREFIX) and k not in cameras)
        if not present and others:  # images under other names: the robot's cameras are misnamed, not dropped
            raise KeyError(
                f"PredVLA's front end needs the camera images {cameras}; the observation has {others}. On a robot, "
                "name its cameras as in the training dataset; in LIBERO, evaluate with --env.type=predvla_libero "
                "(or libero)."
            )
        if not present:  # every camera dropped this step: masked out of the free energy
            return torch.full((batch_size, frontend.artefact.vision_dim), float("nan"))
        batched = {key: x[None] if x.dim() == 3 else x for key, x in present.items()}
        template = next(iter(batched.values()))
        bad = torch.zeros(template.shape[0], dtype=torch.bool, device=template.device)
        images = {}
        for key in cameras:
            x = batched.get(key)
            if x is None:
                x, bad = torch.zeros_like(template), torch.ones_like(bad)
            elif x.is_floating_point():
                rows = ~torch.isfinite(x).flatten(1).all(1)
                x, bad = torch.where(rows[:, None, None, None], torch.zeros((), dtype=x.dtype), x), bad | rows
            images[key] = x
        with torch.no_grad():
            vision = frontend.encode_images(images)
        return torch.where(bad[:, None].to(vision.device), torch.full((), float("nan")), vision)

    @staticmethod
    def _oracle_frame(oracle: OracleStandardisation, observation: dict) -> torch.Tensor:
        """The oracle's standardised object poses (batch, dim); NaN rows where a pose is non-finite."""
        if OBS_ENV_STATE not in observation:
            raise KeyError(
                f"This PredVLA policy was trained with the oracle front end (simulator object poses, `predvla convert "
                f"--oracle`): it needs '{OBS_ENV_STATE}'; evaluate it with --env.type=predvla_libero --env.oracle=true."
            )
        poses = torch.as_tensor(observation[OBS_ENV_STATE]).float()
        poses = poses[None] if poses.dim() == 1 else poses
        if poses.shape[-1] != oracle.dim:
            raise ValueError(f"'{OBS_ENV_STATE}' has {poses.shape[-1]} values per step; the oracle front end was "
                             f"fitted on {oracle.dim} (objects {oracle.objects}).")
        bad = ~torch.isfinite(poses).all(-1, keepdim=True)
        return torch.where(bad, torch.full((), float("nan")), oracle.apply(poses))

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        if self.artefact is None:
            return features
        observation = dict(features.get(PipelineFeatureType.OBSERVATION, {}))
        if "oracle" in self.artefact:
            vision_dim = len(self.artefact["oracle"]["mean"])
        else:
            vision_dim = sum(cam["n_components"] for cam in self.artefact["vision"]["cameras"].values())
        observation[OBS_VISION_FEATURES] = PolicyFeature(type=FeatureType.STATE, shape=(vision_dim,))
        observation[OBS_LANGUAGE_FEATURES] = PolicyFeature(
            type=FeatureType.STATE, shape=(self.artefact["language"]["n_components"],)
        )
        return {**features, PipelineFeatureType.OBSERVATION: observation}
