"""Sensor-fault injection for `lerobot-eval --env.type=predvla_libero` (docs/reliability.md).

`--env.fault_rate=x` spoils a fraction x of the camera frames and of the proprioceptive readings before any
policy sees them, independently per channel, control step and environment, from `--env.fault_seed`:

- `--env.fault_mode=nan` (default): the environment's images (all cameras) or its `observation.state` row
  become NaN, as a sensor reporting garbage;
- `--env.fault_mode=drop`: the channel's keys are removed from the observation for that step, as a sensor
  that delivers nothing. A batch cannot hold a missing row, so a drop hits every environment of the batch
  at that step (the draw is per step).

The counts of spoiled frames go to `eval_info.json` (`predvla_faults.injected`) beside the policy's counts
of masked observations and the environments' count of non-finite actions.
"""

from dataclasses import dataclass, field

import numpy as np
import torch
from lerobot.processor import ObservationProcessorStep, ProcessorStepRegistry
from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

FAULT_MODES = ("nan", "drop")


@ProcessorStepRegistry.register("predvla_fault_injection")
@dataclass
class FaultInjectionStep(ObservationProcessorStep):
    """Replace a fraction `rate` of camera frames and proprio readings by NaN, or drop them.

    Args:
        rate: Fraction in [0, 1] of frames spoiled, per channel.
        mode: "nan" or "drop".
        seed: Seed of the draws.
    """

    rate: float = 0.0
    mode: str = "nan"
    seed: int = 0
    counts: dict[str, int] = field(default_factory=lambda: {"vision": 0, "proprio": 0, "steps": 0}, init=False)
    _rng: np.random.Generator | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not 0.0 <= self.rate <= 1.0:
            raise ValueError(f"--env.fault_rate must lie in [0, 1], got {self.rate}.")
        if self.mode not in FAULT_MODES:
            raise ValueError(f"--env.fault_mode must be one of {FAULT_MODES}, got {self.mode!r}.")
        self._rng = np.random.default_rng(self.seed)

    def get_config(self) -> dict:
        return {"rate": self.rate, "mode": self.mode, "seed": self.seed}

    def observation(self, observation: dict) -> dict:
        out = dict(observation)
        cameras = [k for k in out if k.startswith(f"{OBS_IMAGES}.")]
        size = out[OBS_STATE].shape[0]
        self.counts["steps"] += size
        for channel, keys in (("vision", cameras), ("proprio", [OBS_STATE])):
            if self.mode == "drop":
                if self._rng.random() < self.rate:
                    for key in keys:
                        del out[key]
                    self.counts[channel] += size
                continue
            hit = torch.from_numpy(self._rng.random(size) < self.rate)
            if hit.any():
                for key in keys:
                    x = out[key].float()
                    out[key] = torch.where(hit.view(-1, *([1] * (x.dim() - 1))).to(x.device), float("nan"), x)
                self.counts[channel] += int(hit.sum())
        return out

    def transform_features(self, features):
        return features
