"""Unavailable observations at acting time: detected per channel and environment, kept out of inference.

Sensors drop frames and report garbage. A channel (vision features, proprioception, language features) is
unavailable for one environment at one control step when its key is missing from the batch or its row holds
a NaN or an infinite value (e.g. a camera frame the front end could not encode). With `on_bad_observation=
"mask"` (default) the row is replaced by zeros and flagged, so that the policy leaves it out: PredVLA drops
its prediction error from the free energy (Section 3.3, "prediction-error terms are masked when the
corresponding observation is unavailable"), the observation-driven baselines hold their last available
input. With "raise" the step stops with an error naming the channel, the environment and the step.

Each environment is handled on its own row: one environment's bad frame changes nothing for the others.
Counts are kept per channel and environment and logged at the next reset and, while frames keep being masked,
at least every `REPORT_INTERVAL_S` seconds (a robot's rollout may never reset). The last line of defence is
`safe_action`: any action row that is still non-finite is replaced by a finite fallback.
"""

import logging
import time

import numpy as np
import torch
from lerobot.utils.constants import OBS_STATE
from torch import Tensor

from lerobot_predvla.columns import OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES

FALLBACK = "fallback_actions"  # count of non-finite actions replaced by `safe_action`
REPORT_INTERVAL_S = 10.0  # longest time between two log lines while observations are being masked


class BadObservationError(ValueError):
    """An unavailable observation with `on_bad_observation="raise"`."""


class ObservationGuard:
    """Availability of each observation channel per environment, with counts for the episode report.

    Args:
        keys: Batch keys of the observation channels, each (batch, dim) or (dim,).
        dims: Their feature sizes (a missing key is filled with zeros of this size).
        mode: `on_bad_observation`, "mask" or "raise" (see the module docstring).
        name: Policy name used in messages.
        report_interval_s: Log the counts at least this often while observations are being masked.
    """

    def __init__(
        self, keys: tuple[str, ...], dims: tuple[int, ...], mode: str, name: str,
        report_interval_s: float = REPORT_INTERVAL_S,
    ):
        self.keys, self.dims, self.mode, self.name = keys, dims, mode, name
        self.report_interval_s = report_interval_s
        self.totals = {key: 0 for key in (*keys, FALLBACK)}  # since construction, all episodes
        self.reset()

    @classmethod
    def for_policy(cls, config, name: str) -> "ObservationGuard":
        """The guard of a policy that reads language, vision features and proprioception (in that order)."""
        return cls(
            (OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES, OBS_STATE),
            (config.language_dim, config.vision_dim, config.proprio_dim), config.on_bad_observation, name,
        )

    def reset(self) -> None:
        """Log the finished episode's counts (if any channel was unavailable) and start a new episode."""
        if getattr(self, "counts", None):
            self.report()
        self.counts: dict[str, np.ndarray] = {}  # per key: (batch,) number of unavailable steps
        self.step = 0
        self.reported_at = time.monotonic()

    def report(self) -> str | None:
        """One log line with the current episode's counts per channel and environment; None if all clean."""
        self.reported_at = time.monotonic()
        parts = [
            f"{'non-finite actions replaced' if key == FALLBACK else key + ' unavailable (masked)'} at "
            f"{int(c.sum())} env-steps (per env {c.tolist()})"
            for key, c in self.counts.items() if int(c.sum()) > 0
        ]
        if not parts:
            return None
        line = f"{self.name}: episode of {self.step} control steps: " + "; ".join(parts) + "."
        logging.warning(line)
        return line

    def _count(self, key: str, bad: Tensor) -> None:
        bad = bad.cpu().numpy()
        count = self.counts.setdefault(key, np.zeros(bad.shape[0], dtype=np.int64))
        if count.shape[0] != bad.shape[0]:
            raise ValueError(f"{self.name}: batch size changed within an episode ({count.shape[0]} -> {bad.shape[0]}).")
        count += bad
        self.totals[key] += int(bad.sum())

    def __call__(self, batch: dict[str, Tensor]) -> tuple[list[Tensor], list[Tensor]]:
        """This control step's channels, each (batch, dim) with unavailable rows zeroed, and their
        availability, each a (batch,) bool tensor."""
        present = [batch[k] for k in self.keys if k in batch]
        if not present:
            raise BadObservationError(f"{self.name}: the observation has none of {list(self.keys)}.")
        reference = present[0][None] if present[0].dim() == 1 else present[0]
        size, device = reference.shape[0], reference.device
        values, available = [], []
        for key, dim in zip(self.keys, self.dims, strict=True):
            x = batch.get(key)
            if x is None:
                x = torch.zeros(size, dim, device=device)
                ok = torch.zeros(size, dtype=torch.bool, device=device)
            else:
                x = x[None] if x.dim() == 1 else x
                ok = torch.isfinite(x).all(-1)
            if not bool(ok.all()):
                if self.mode == "raise":
                    env = int((~ok).nonzero()[0])
                    what = "missing" if key not in batch else "non-finite"
                    raise BadObservationError(
                        f"{self.name}: observation '{key}' of environment {env} is {what} at control step "
                        f"{self.step}; --policy.on_bad_observation=mask masks it out instead of stopping."
                    )
                x = torch.where(ok[:, None], x, torch.zeros((), dtype=x.dtype, device=device))
            self._count(key, ~ok)
            values.append(x)
            available.append(ok)
        self.step += 1
        if time.monotonic() - self.reported_at >= self.report_interval_s:
            self.report()  # logs only if something was masked; an endless episode is reported as it goes
        return values, available

    def safe_action(self, action: Tensor, fallback: Tensor | None = None) -> Tensor:
        """The action with every non-finite row replaced by `fallback`'s row (zeros where that is not finite
        either), counted under `FALLBACK`."""
        bad = ~torch.isfinite(action).all(-1)
        if not bool(bad.any()):
            return action
        if fallback is None:
            fallback = torch.zeros_like(action)
        fallback = torch.where(torch.isfinite(fallback), fallback, torch.zeros((), dtype=action.dtype))
        self._count(FALLBACK, bad)
        logging.warning(
            "%s: non-finite action for environments %s at control step %d; sent the fallback action instead.",
            self.name, bad.nonzero().flatten().tolist(), self.step - 1,
        )
        return torch.where(bad[:, None], fallback.to(action.dtype), action)
