"""The fitted front-end artefact: `frontend.safetensors` (PCA arrays) + `frontend.json` (identities)."""

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from safetensors.numpy import load_file, save_file

from lerobot_predvla.frontend.language import LANGUAGE_ENCODER_DIM, LANGUAGE_ENCODER_NAME
from lerobot_predvla.frontend.oracle import OracleStandardisation
from lerobot_predvla.frontend.pca import PCABasis
from lerobot_predvla.frontend.preprocessing import PreprocessingSpec
from lerobot_predvla.frontend.vision import VISION_ENCODER_DIM, VISION_ENCODER_NAME, VisionWeights
from lerobot_predvla.utils.finite import NonFiniteError, check_finite

TENSORS_FILE = "frontend.safetensors"
METADATA_FILE = "frontend.json"
FORMAT = "predvla-frontend"
FORMAT_VERSION = 1
_ARRAYS = ("mean", "components", "explained_variance", "explained_variance_ratio")


class FrontendArtefactError(ValueError):
    """A missing, malformed or mismatching front-end artefact."""


@dataclass
class FrontendArtefact:
    """Everything needed to recompute PredVLA's cached features exactly.

    Args:
        language: PCA basis of the sentence embeddings (384 -> language_dim).
        cameras: Per-camera PCA bases (512 -> vision_dim_per_camera), in concatenation order, keyed
            by LeRobot camera key.
        vision_weights: The ResNet18 weights the bases were fitted with.
        vision_fingerprint: SHA-256 of those weights; loading checks it.
        vision_precision: "bf16" or "fp32", the precision features are computed in.
        language_source: Where all-MiniLM-L6-v2 was loaded from.
        language_fingerprint: SHA-256 of the sentence encoder's weights; loading checks it.
        preprocessing: The image preprocessing.
        fit: Provenance of the fit (suites, files, demonstrations, frames, instructions).
        oracle: Set only in a dataset converted with `predvla convert --oracle`: its visual features are the
            oracle's standardised object poses (`frontend.oracle`), not the cameras' PCA features.
    """

    language: PCABasis
    cameras: dict[str, PCABasis]
    vision_weights: VisionWeights
    vision_fingerprint: str
    vision_precision: str
    language_source: str
    language_fingerprint: str
    preprocessing: PreprocessingSpec
    fit: dict = field(default_factory=dict)
    oracle: OracleStandardisation | None = None

    @property
    def language_dim(self) -> int:
        return self.language.n_components

    @property
    def vision_dim_per_camera(self) -> int:
        return next(iter(self.cameras.values())).n_components

    @property
    def vision_dim(self) -> int:
        """Size of the visual feature: the cameras' PCA components, or the oracle's poses."""
        if self.oracle is not None:
            return self.oracle.dim
        return sum(basis.n_components for basis in self.cameras.values())

    def _bases(self) -> dict[str, PCABasis]:
        return {"language": self.language, **{f"vision/{cam}": basis for cam, basis in self.cameras.items()}}

    def metadata(self) -> dict:
        """The JSON description (everything except the arrays)."""

        def basis_info(basis: PCABasis) -> dict:
            return {
                "input_dim": basis.input_dim,
                "n_components": basis.n_components,
                "components_with_variance": basis.components_with_variance,
                "num_samples": basis.num_samples,
            }

        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "language": {
                "encoder": LANGUAGE_ENCODER_NAME,
                "source": self.language_source,
                "fingerprint_sha256": self.language_fingerprint,
                **basis_info(self.language),
                "note": "Components beyond components_with_variance have zero variance: their rows are "
                "zero, so those feature dimensions are always 0 (fewer distinct instructions than components).",
            },
            "vision": {
                "encoder": VISION_ENCODER_NAME,
                "weights": self.vision_weights.to_dict(),
                "weights_description": self.vision_weights.describe(),
                "fingerprint_sha256": self.vision_fingerprint,
                "precision": self.vision_precision,
                "cameras": {cam: basis_info(basis) for cam, basis in self.cameras.items()},
            },
            "preprocessing": self.preprocessing.to_dict(),
            "fit": self.fit,
            **({"oracle": self.oracle.metadata()} if self.oracle is not None else {}),
        }

    def tensors(self) -> dict[str, np.ndarray]:
        """The PCA arrays, keyed `<basis>/<array>` (what `frontend.safetensors` holds)."""
        return {f"{name}/{array}": getattr(basis, array) for name, basis in self._bases().items() for array in _ARRAYS}

    def save(self, directory: Path | str) -> Path:
        """Write both files into `directory` (each replaced atomically)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        tensors = self.tensors()
        for file, write in (
            (TENSORS_FILE, lambda p: save_file(tensors, p, metadata={"format": FORMAT})),
            (METADATA_FILE, lambda p: Path(p).write_text(json.dumps(self.metadata(), indent=2) + "\n")),
        ):
            tmp = directory / f".{file}.tmp"
            write(str(tmp))
            os.replace(tmp, directory / file)
        return directory

    @classmethod
    def load(cls, directory: Path | str) -> "FrontendArtefact":
        directory = Path(directory)
        meta_path, tensor_path = directory / METADATA_FILE, directory / TENSORS_FILE
        for path in (meta_path, tensor_path):
            if not path.is_file():
                raise FrontendArtefactError(f"{path}: missing; run `predvla fit-frontend --out {directory}`.")
        try:
            meta = json.loads(meta_path.read_text())
            tensors = load_file(str(tensor_path))
        except Exception as err:  # json and safetensors raise various types on corrupt files.
            raise FrontendArtefactError(f"{directory}: unreadable front-end artefact ({err}).") from err
        return cls.from_metadata(meta, tensors, where=directory)

    @classmethod
    def from_metadata(
        cls, meta: dict, tensors: dict[str, np.ndarray], where: Path | str
    ) -> "FrontendArtefact":
        """Rebuild an artefact from its JSON description and arrays (`where` names the source in errors).

        Every array must have the shape its JSON description gives, and the arrays that encode features
        (`mean`, `components`) must be finite."""
        if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
            raise FrontendArtefactError(f"{where}: not a {FORMAT} v{FORMAT_VERSION} artefact.")
        try:
            return cls._from_checked_metadata(meta, tensors, where)
        except (KeyError, TypeError) as err:
            raise FrontendArtefactError(f"{where}: malformed {METADATA_FILE}, no field {err}.") from err
        except NonFiniteError as err:
            raise FrontendArtefactError(str(err)) from err

    @classmethod
    def _from_checked_metadata(
        cls, meta: dict, tensors: dict[str, np.ndarray], where: Path | str
    ) -> "FrontendArtefact":
        def basis(name: str, info: dict) -> PCABasis:
            n, d = info["n_components"], info["input_dim"]
            shapes = {"mean": (d,), "components": (n, d), "explained_variance": (n,), "explained_variance_ratio": (n,)}
            arrays = {}
            for array, shape in shapes.items():
                key = f"{name}/{array}"
                if key not in tensors:
                    raise FrontendArtefactError(f"{where}: missing tensor '{key}'.")
                arrays[array] = np.asarray(tensors[key])
                if arrays[array].shape != shape:
                    raise FrontendArtefactError(
                        f"{where}: tensor '{key}' has shape {arrays[array].shape}, {METADATA_FILE} says {shape}."
                    )
            for array in ("mean", "components"):  # the ratio is NaN when the fitting data had no variance
                check_finite(arrays[array], str(where), f"{name}/{array}")
            return PCABasis(**arrays, components_with_variance=info["components_with_variance"],
                            num_samples=info["num_samples"])

        def oracle(info: dict) -> OracleStandardisation:
            try:
                return OracleStandardisation.from_metadata(info)
            except ValueError as err:
                raise FrontendArtefactError(f"{where}: {err}") from err

        vision = meta["vision"]
        return cls(
            language=basis("language", meta["language"]),
            cameras={cam: basis(f"vision/{cam}", info) for cam, info in vision["cameras"].items()},
            vision_weights=VisionWeights(**vision["weights"]),
            vision_fingerprint=vision["fingerprint_sha256"],
            vision_precision=vision["precision"],
            language_source=meta["language"]["source"],
            language_fingerprint=meta["language"]["fingerprint_sha256"],
            preprocessing=PreprocessingSpec.from_dict(meta["preprocessing"]),
            fit=meta["fit"],
            oracle=oracle(meta["oracle"]) if "oracle" in meta else None,
        )

    def check_dims(
        self, language_dim: int, vision_dim_per_camera: int, camera_keys: list[str], where: Path | str
    ) -> None:
        """Raise if the artefact does not produce the requested feature dimensions and cameras."""
        meta = Path(where) / METADATA_FILE
        problems = []
        if self.language_dim != language_dim:
            problems.append(f"language.n_components is {self.language_dim}, requested {language_dim}")
        if list(self.cameras) != list(camera_keys):
            problems.append(f"vision.cameras are {list(self.cameras)}, requested {list(camera_keys)}")
        for cam, b in self.cameras.items():
            if b.n_components != vision_dim_per_camera:
                problems.append(
                    f"vision.cameras[{cam}].n_components is {b.n_components}, requested {vision_dim_per_camera}"
                )
        if self.language.input_dim != LANGUAGE_ENCODER_DIM:
            problems.append(f"language.input_dim is {self.language.input_dim}, expected {LANGUAGE_ENCODER_DIM}")
        for cam, b in self.cameras.items():
            if b.input_dim != VISION_ENCODER_DIM:
                problems.append(f"vision.cameras[{cam}].input_dim is {b.input_dim}, expected {VISION_ENCODER_DIM}")
        if problems:
            raise FrontendArtefactError(f"{meta}: front end does not match: " + "; ".join(problems) + ".")

