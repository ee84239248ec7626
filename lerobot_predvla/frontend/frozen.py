"""The fitted frozen front end at work: raw images / instructions -> PredVLA's cached features."""

from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path

import numpy as np
import torch

from lerobot_predvla.frontend.artefact import FrontendArtefact, FrontendArtefactError
from lerobot_predvla.frontend.language import LanguageEncoder
from lerobot_predvla.frontend.preprocessing import preprocess_images
from lerobot_predvla.frontend.vision import VisionEncoder


class FrozenFrontend:
    """Encoders rebuilt from an artefact's recorded identities, plus its PCA bases.

    Used identically by the converter (`predvla convert`) and at evaluation, so cached and live features
    agree. Images must be in LeRobot's LIBERO orientation (see `preprocessing`).

    Args:
        artefact: The fitted artefact.
        device: Torch device of the encoders.
        batch_size: Images per ResNet18 forward pass.
        verbose: Print the encoder choices.
    """

    def __init__(
        self, artefact: FrontendArtefact, device: str = "cpu", batch_size: int = 64, verbose: bool = True
    ):
        self.artefact = artefact
        self.device = device
        self.verbose = verbose
        self.vision = VisionEncoder(
            artefact.vision_weights, artefact.vision_precision, batch_size=batch_size, device=device,
            verbose=verbose,
        )
        if self.vision.fingerprint != artefact.vision_fingerprint:
            raise FrontendArtefactError(
                f"The vision weights ({artefact.vision_weights.describe()}) hash to "
                f"{self.vision.fingerprint[:12]}..., but the front end was fitted with "
                f"{artefact.vision_fingerprint[:12]}...: the features would not match its PCA bases."
            )

    @classmethod
    def load(cls, directory: Path | str, **kwargs) -> "FrozenFrontend":
        return cls(FrontendArtefact.load(directory), **kwargs)

    @cached_property
    def language(self) -> LanguageEncoder:
        """The sentence encoder, loaded on first use (it takes seconds)."""
        encoder = LanguageEncoder(self.device, verbose=self.verbose)
        if encoder.fingerprint != self.artefact.language_fingerprint:
            raise FrontendArtefactError(
                f"all-MiniLM-L6-v2 from {encoder.source} differs from the one the front end was fitted with "
                f"({self.artefact.language_source})."
            )
        return encoder

    def fitted_precision(self) -> torch.autocast:
        """No enclosing autocast reaches the encoders or the PCA bases (`lerobot-eval` wraps the preprocessor in one
        when a policy has `use_amp`): features come at the artefact's own precision, as the converter cached them."""
        return torch.autocast(torch.device(self.device).type, enabled=False)

    def encode_images(self, images: Mapping[str, torch.Tensor | np.ndarray]) -> torch.Tensor:
        """Visual features (N, num_cameras * vision_dim_per_camera) from per-camera image batches.

        Args:
            images: For every camera key of the artefact, uint8 (N, H, W, 3) or float (N, 3, H, W)
                images in LeRobot orientation.
        """
        features = []
        with self.fitted_precision():
            for camera, basis in self.artefact.cameras.items():
                if camera not in images:
                    raise KeyError(f"Missing camera '{camera}'; the front end needs {list(self.artefact.cameras)}.")
                pixels = preprocess_images(images[camera], self.artefact.preprocessing)
                features.append(basis.transform(self.vision(pixels)))
        return torch.cat(features, dim=-1)

    def encode_instructions(self, texts: Sequence[str]) -> torch.Tensor:
        """Language features (N, language_dim) of instructions, bit-identical for identical strings."""
        unique = sorted(set(texts))
        with self.fitted_precision():
            embeddings = torch.from_numpy(self.language(unique))
            # Row by row: a matmul's rounding can depend on how many rows it has.
            rows = {text: self.artefact.language.transform(e[None])[0]
                    for text, e in zip(unique, embeddings, strict=True)}
        return torch.stack([rows[t] for t in texts]) if texts else torch.zeros(0, self.artefact.language_dim)
