"""PredVLA's frozen front end (paper Section 3.1): ResNet18 + all-MiniLM-L6-v2 with fixed PCA bases."""

from lerobot_predvla.frontend.artefact import FrontendArtefact, FrontendArtefactError
from lerobot_predvla.frontend.frozen import FrozenFrontend
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec, libero_hdf5_to_lerobot, preprocess_images
from lerobot_predvla.frontend.vision import VisionWeights, VisionWeightsError

__all__ = [
    "FrontendArtefact",
    "FrontendArtefactError",
    "FrozenFrontend",
    "PreprocessingSpec",
    "VisionWeights",
    "VisionWeightsError",
    "libero_hdf5_to_lerobot",
    "preprocess_images",
]
