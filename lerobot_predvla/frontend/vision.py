"""Frozen ResNet18 image encoder (Section 3.1): global-pooled 512-d features per camera."""

import hashlib
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import nn
from torchvision.models import ResNet18_Weights, resnet18

VISION_ENCODER_NAME = "torchvision.models.resnet18 (global average pool, fc removed)"
VISION_ENCODER_DIM = 512
PRECISIONS = ("bf16", "fp32")


class VisionWeightsError(RuntimeError):
    """The requested ResNet18 weights cannot be loaded (never silently replaced)."""


def module_fingerprint(module: nn.Module) -> str:
    """SHA-256 of a module's state dict (names, dtypes, shapes and values), identifying its weights."""
    digest = hashlib.sha256()
    for name, tensor in module.state_dict().items():
        t = tensor.detach().cpu().contiguous()
        digest.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        digest.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


@dataclass(frozen=True)
class VisionWeights:
    """Which ResNet18 weights to use, as chosen with `--vision-weights imagenet|PATH.pth|random`.

    Args:
        source: "imagenet" (torchvision IMAGENET1K_V1, the paper's setting), "file" or "random".
        path: The `.pth` state dict when `source == "file"`.
        seed: Seed of the frozen random initialisation when `source == "random"`.
    """

    source: str
    path: str | None = None
    seed: int | None = None

    @classmethod
    def parse(cls, spec: str, seed: int = 0) -> "VisionWeights":
        if spec == "imagenet":
            return cls("imagenet")
        if spec == "random":
            return cls("random", seed=seed)
        if spec.endswith((".pth", ".pt")):
            return cls("file", path=str(Path(spec).expanduser().resolve()))
        raise ValueError(f"--vision-weights must be 'imagenet', 'random' or a .pth/.pt path, got {spec!r}.")

    def describe(self) -> str:
        if self.source == "imagenet":
            return "ImageNet (torchvision IMAGENET1K_V1, the paper's setting)"
        if self.source == "file":
            return f"state dict from {self.path}"
        return f"RANDOM frozen initialisation, seed {self.seed} (NOT the paper's ImageNet weights)"

    def to_dict(self) -> dict:
        return asdict(self)


def build_resnet18(weights: VisionWeights) -> nn.Module:
    """ResNet18 with the requested weights and its classifier replaced by the identity."""
    if weights.source == "imagenet":
        try:
            model = resnet18(weights=ResNet18_Weights.IMAGENET1K_V1)
        except Exception as err:  # Download failures come in many types (URLError, OSError, ...).
            raise VisionWeightsError(
                "Could not load torchvision's ImageNet ResNet18 weights (IMAGENET1K_V1): "
                f"{type(err).__name__}: {err}. Put resnet18-f37072fd.pth in $TORCH_HOME/hub/checkpoints, "
                "pass --vision-weights PATH.pth, or choose --vision-weights random explicitly."
            ) from err
    elif weights.source == "file":
        model = resnet18(weights=None)
        path = Path(weights.path)
        if not path.is_file():
            raise VisionWeightsError(f"Vision weights file {path} does not exist.")
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
            state = {k: v for k, v in state.items() if not k.startswith("fc.")}
            missing, unexpected = model.load_state_dict(state, strict=False)
        except Exception as err:  # Unpickling and shape errors come in many types.
            raise VisionWeightsError(f"{path} is not a ResNet18 state dict: {err}") from err
        missing = [k for k in missing if not k.startswith("fc.")]
        if missing or unexpected:
            raise VisionWeightsError(
                f"{path} is not a ResNet18 state dict: missing {missing[:5]}, unexpected {unexpected[:5]}."
            )
    elif weights.source == "random":
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(weights.seed)
            model = resnet18(weights=None)
    else:
        raise ValueError(f"Unknown vision weight source {weights.source!r}.")
    model.fc = nn.Identity()
    return model.eval().requires_grad_(False)


class VisionEncoder:
    """Batched frozen ResNet18 feature extractor.

    Args:
        weights: The weights to load (printed loudly).
        precision: "fp32" in full precision, or "bf16" under bfloat16 autocast (fast on CPUs with native bfloat16).
        channels_last: Use the channels-last memory format (faster convolutions on CPU).
        batch_size: Images per forward pass.
        device: Torch device.
        verbose: Print the weight choice.
    """

    def __init__(
        self,
        weights: VisionWeights,
        precision: str = "fp32",
        channels_last: bool = True,
        batch_size: int = 64,
        device: str | torch.device = "cpu",
        verbose: bool = True,
    ):
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}.")
        self.weights = weights
        self.precision = precision
        self.channels_last = channels_last
        self.batch_size = batch_size
        self.device = torch.device(device)
        model = build_resnet18(weights)
        self.fingerprint = module_fingerprint(model)
        if verbose:
            print(f"[predvla] vision encoder: ResNet18, weights = {weights.describe()}, precision {precision}")
        if channels_last:
            model = model.to(memory_format=torch.channels_last)
        self.model = model.to(self.device)

    @torch.inference_mode()
    def __call__(self, images: torch.Tensor) -> torch.Tensor:
        """Encode preprocessed images (N, 3, S, S) into float32 features (N, 512) on the CPU."""
        outputs = []
        for batch in images.split(self.batch_size):
            batch = batch.to(self.device)
            if self.channels_last:
                batch = batch.contiguous(memory_format=torch.channels_last)
            with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.precision == "bf16"):
                outputs.append(self.model(batch).float().cpu())
        return torch.cat(outputs) if outputs else torch.empty(0, VISION_ENCODER_DIM)
