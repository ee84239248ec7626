"""Fixed PCA bases of the front end (scikit-learn), robust to fewer samples than components."""

from dataclasses import dataclass

import numpy as np
import torch
from sklearn.decomposition import PCA

# Components whose variance is below this fraction of the largest are numerical noise (rank deficiency).
RANK_TOLERANCE = 1e-10


@dataclass
class PCABasis:
    """A fixed projection `x -> (x - mean) @ components.T`.

    Components beyond the rank of the fitting data (e.g. LIBERO's 40 distinct instructions span at most
    39 directions, fewer than the 64 language components) are stored as zero rows with zero variance,
    so those output dimensions are exactly 0 instead of arbitrary round-off directions.

    Args:
        mean: (input_dim,) sample mean.
        components: (n_components, input_dim) orthonormal rows, zero beyond `components_with_variance`.
        explained_variance: (n_components,) variance along each component.
        explained_variance_ratio: (n_components,) fraction of the total variance along each component.
        components_with_variance: Number of leading components that carry variance.
        num_samples: Number of samples the basis was fitted on.
    """

    mean: np.ndarray
    components: np.ndarray
    explained_variance: np.ndarray
    explained_variance_ratio: np.ndarray
    components_with_variance: int
    num_samples: int

    @property
    def n_components(self) -> int:
        return self.components.shape[0]

    @property
    def input_dim(self) -> int:
        return self.components.shape[1]

    def transform(self, x: torch.Tensor) -> torch.Tensor:
        """Project float features (N, input_dim) to (N, n_components) in float32."""
        mean = torch.from_numpy(self.mean).to(x.device)
        components = torch.from_numpy(self.components).to(x.device)
        return (x.to(torch.float32) - mean) @ components.T


def fit_pca(samples: np.ndarray, n_components: int) -> PCABasis:
    """Fit a PCA basis with exactly `n_components` outputs on (N, D) samples (computed in float64)."""
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 1:
        raise ValueError(f"PCA needs a non-empty (N, D) sample matrix, got shape {x.shape}.")
    num_samples, input_dim = x.shape
    if not 1 <= n_components <= input_dim:
        raise ValueError(f"Cannot fit {n_components} components on {input_dim}-d features.")
    components = np.zeros((n_components, input_dim))
    explained = np.zeros(n_components)
    mean, rank = x.mean(axis=0), 0
    if num_samples > 1:
        # Deterministic solvers only: eigh of the covariance for tall data, exact SVD otherwise.
        solver = "covariance_eigh" if num_samples >= 10 * input_dim else "full"
        pca = PCA(n_components=min(n_components, num_samples), svd_solver=solver).fit(x)
        variance = np.clip(pca.explained_variance_, 0.0, None)
        rank = int((variance > RANK_TOLERANCE * variance[0]).sum()) if variance[0] > 0 else 0
        components[:rank] = pca.components_[:rank]
        explained[:rank] = variance[:rank]
        mean = pca.mean_
    total = x.var(axis=0, ddof=1).sum() if num_samples > 1 else 0.0
    return PCABasis(
        mean=mean.astype(np.float32),
        components=components.astype(np.float32),
        explained_variance=explained.astype(np.float32),
        explained_variance_ratio=(explained / total if total > 0 else explained).astype(np.float32),
        components_with_variance=rank,
        num_samples=num_samples,
    )
