"""The oracle front end: simulator object poses relative to the gripper in place of the visual features.

A diagnostic, never PredVLA's front end (Section 3.1 is ResNet18 + PCA): it asks whether error regression is
limited by what the visual features say about where the objects are. Each object of interest contributes its
position (m) and orientation in the gripper's frame, as LIBERO's own `<object>_to_robot0_eef_pos/quat` sensors
report them (`libero.oracle`); the orientation as the first two columns of its rotation matrix (a continuous
representation: a top-down gripper sees an upright object near a half turn, where rotation vectors jump). Every
dimension is standardised with the mean and standard
deviation of the training demonstrations (scikit-learn's `StandardScaler`). The standardisation is stored in the
front-end artefact (its `oracle` section), so evaluation standardises the live poses exactly as the converter did.
"""

from dataclasses import dataclass

import numpy as np
import torch
from sklearn.preprocessing import StandardScaler

POSE_DIM = 9  # per object: position (3) + the rotation matrix's first two columns (6), in the gripper's frame


@dataclass(frozen=True)
class OracleStandardisation:
    """Per-dimension standardisation of the oracle's object poses.

    Args:
        objects: Per task instruction, the objects of interest whose poses make the feature, in order.
        mean: (dim,) mean of the training poses.
        std: (dim,) their standard deviation (1 where a dimension does not vary).
    """

    objects: dict[str, list[str]]
    mean: np.ndarray
    std: np.ndarray

    @property
    def dim(self) -> int:
        return len(self.mean)

    @classmethod
    def fit(cls, poses: np.ndarray, objects: dict[str, list[str]]) -> "OracleStandardisation":
        """Fit on every training frame's poses (N, dim)."""
        scaler = StandardScaler().fit(np.asarray(poses, dtype=np.float64))
        return cls(objects, scaler.mean_.astype(np.float32), scaler.scale_.astype(np.float32))

    def apply(self, poses: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
        """Standardised features from raw poses (..., dim), as numpy or torch (float32)."""
        if isinstance(poses, torch.Tensor):
            mean, std = torch.from_numpy(self.mean).to(poses.device), torch.from_numpy(self.std).to(poses.device)
            return (poses.float() - mean) / std
        return ((np.asarray(poses, dtype=np.float32) - self.mean) / self.std).astype(np.float32)

    def metadata(self) -> dict:
        """The JSON description kept in the artefact's `oracle` section (small: a few numbers per dimension)."""
        return {
            "description": "oracle: simulator object poses relative to the gripper (position m, rotation matrix's "
            "first two columns, per object of interest), standardised; not images",
            "objects": self.objects,
            "mean": self.mean.tolist(),
            "std": self.std.tolist(),
        }

    @classmethod
    def from_metadata(cls, meta: dict) -> "OracleStandardisation":
        mean, std = np.asarray(meta["mean"], dtype=np.float32), np.asarray(meta["std"], dtype=np.float32)
        if mean.shape != std.shape or mean.ndim != 1 or not (np.isfinite(mean).all() and (std > 0).all()):
            raise ValueError(f"oracle section: mean and std must be finite vectors of one length with std > 0, "
                             f"got shapes {mean.shape} and {std.shape}.")
        return cls({k: list(v) for k, v in meta["objects"].items()}, mean, std)
