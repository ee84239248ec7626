"""The single image preprocessing path shared by the converter and evaluation.

Orientation convention: images are consumed as LeRobot's LIBERO environment delivers them, i.e. after
`LiberoProcessorStep`, which rotates the raw (upside-down) MuJoCo renders by 180 degrees. The original
LIBERO hdf5 files hold the raw renders, so the converter rotates them once with
`libero_hdf5_to_lerobot` and stores, encodes and serves that same array. The simulator path needs no
rotation of its own: LeRobot's processor has already applied it.
"""

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torchvision.transforms.v2 import InterpolationMode
from torchvision.transforms.v2 import functional as tvf

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
ORIENTATION = "lerobot_libero: raw LIBERO/robosuite renders rotated by 180 degrees (H and W flipped)"


@dataclass(frozen=True)
class PreprocessingSpec:
    """How camera images become ResNet18 inputs (stored in the front-end artefact).

    Args:
        image_size: Square side the images are resized to (LIBERO's demonstrations are 128 x 128, so the
            default leaves them untouched and keeps the encoder cheap).
        interpolation: torchvision interpolation mode used when resizing.
        antialias: Whether resizing anti-aliases (matters only when downscaling).
        mean: Per-channel normalisation mean (ImageNet).
        std: Per-channel normalisation standard deviation (ImageNet).
        orientation: The orientation convention the inputs are expected in (see module docstring).
    """

    image_size: int = 128
    interpolation: str = "bilinear"
    antialias: bool = True
    mean: tuple[float, float, float] = IMAGENET_MEAN
    std: tuple[float, float, float] = IMAGENET_STD
    orientation: str = ORIENTATION

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "PreprocessingSpec":
        return cls(**{**data, "mean": tuple(data["mean"]), "std": tuple(data["std"])})


def libero_hdf5_to_lerobot(images: np.ndarray) -> np.ndarray:
    """Rotate raw LIBERO hdf5 images (N, H, W, 3) by 180 degrees, as `LiberoProcessorStep` does."""
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"Expected images of shape (N, H, W, 3), got {images.shape}.")
    return np.ascontiguousarray(images[:, ::-1, ::-1])


def preprocess_images(images: torch.Tensor | np.ndarray, spec: PreprocessingSpec) -> torch.Tensor:
    """Turn a batch of images in LeRobot orientation into normalised ResNet18 inputs.

    Args:
        images: Either uint8 (N, H, W, 3) pixels (hdf5, dataset writing) or float (N, 3, H, W) in
            [0, 1] (what LeRobot's env preprocessing and `LeRobotDataset` deliver). uint8 pixels are
            divided by 255 in float32, exactly as LeRobot does, so both routes give identical inputs.
        spec: The preprocessing recorded in the front-end artefact.

    Returns:
        float32 (N, 3, image_size, image_size) ImageNet-normalised tensor.
    """
    x = torch.as_tensor(images)
    if x.dtype == torch.uint8:
        if x.ndim != 4 or x.shape[-1] != 3:
            raise ValueError(f"uint8 images must be (N, H, W, 3), got {tuple(x.shape)}.")
        x = x.permute(0, 3, 1, 2).to(torch.float32) / 255
    elif x.is_floating_point():
        if x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"Float images must be (N, 3, H, W) in [0, 1], got {tuple(x.shape)}.")
        x = x.to(torch.float32)
    else:
        raise TypeError(f"Images must be uint8 or floating point, got {x.dtype}.")
    if tuple(x.shape[-2:]) != (spec.image_size, spec.image_size):
        x = tvf.resize(
            x,
            [spec.image_size, spec.image_size],
            interpolation=InterpolationMode(spec.interpolation),
            antialias=spec.antialias,
        )
    mean = torch.tensor(spec.mean, dtype=torch.float32, device=x.device).view(1, 3, 1, 1)
    std = torch.tensor(spec.std, dtype=torch.float32, device=x.device).view(1, 3, 1, 1)
    return (x - mean) / std
