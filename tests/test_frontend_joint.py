"""One front end fitted jointly on several suites' demonstrations (Section 4.1: the PCA bases are fitted on the
training demonstrations of all four suites), from suites made in different folders."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from libero_factory import run_cli, write_libero_file
from sklearn.decomposition import PCA

from lerobot_predvla.columns import HDF5_CAMERAS
from lerobot_predvla.frontend import FrontendArtefact, PreprocessingSpec, libero_hdf5_to_lerobot, preprocess_images
from lerobot_predvla.frontend.artefact import METADATA_FILE, TENSORS_FILE
from lerobot_predvla.frontend.vision import VisionEncoder, VisionWeights

SOUP, DRAWER = "pick up the alphabet soup and place it in the basket", "open the middle drawer of the cabinet"
RANDOM_WEIGHTS = ["--vision-weights", "random", "--vision-seed", "5"]


@pytest.fixture(scope="module")
def roots(tmp_path_factory) -> tuple[Path, Path, Path]:
    """The same demonstrations twice: both suites in one root, and each suite in a root of its own."""
    base = tmp_path_factory.mktemp("roots")
    for root, goal_root in ((base / "one", base / "one"), (base / "object", base / "goal")):
        write_libero_file(root / "libero_object" / "soup_demo.hdf5", SOUP, [6, 5], seed=1)
        write_libero_file(goal_root / "libero_goal" / "drawer_demo.hdf5", DRAWER, [7], seed=3)
    return base / "one", base / "object", base / "goal"


def fit(out: Path, *roots: Path, suites: str = "libero_object,libero_goal", stride: int = 1) -> int:
    hdf5 = [arg for root in roots for arg in ("--hdf5-root", str(root))]
    return run_cli(["fit-frontend", *hdf5, "--suites", suites, *RANDOM_WEIGHTS, "--language-from", "libero",
                    "--frame-stride", str(stride), "--out", str(out)])


def test_the_joint_fit_is_pca_on_the_pooled_frames_of_both_suites(roots, tmp_path):
    one, object_root, goal_root = roots
    assert fit(tmp_path / "joint", object_root, goal_root) == 0
    assert fit(tmp_path / "one", one) == 0
    # Two folders give the artefact one folder gives: the same frames in the same order.
    assert (tmp_path / "joint" / TENSORS_FILE).read_bytes() == (tmp_path / "one" / TENSORS_FILE).read_bytes()
    artefact = FrontendArtefact.load(tmp_path / "joint")
    vision = VisionEncoder(VisionWeights.parse("random", 5), "fp32")
    for camera, key in HDF5_CAMERAS.items():
        frames = []
        for path in (object_root / "libero_object" / "soup_demo.hdf5", goal_root / "libero_goal" / "drawer_demo.hdf5"):
            with h5py.File(path, "r") as f:
                frames += [f["data"][demo]["obs"][key][()] for demo in f["data"]]
        pixels = preprocess_images(libero_hdf5_to_lerobot(np.concatenate(frames)), PreprocessingSpec())
        features = vision(pixels).numpy().astype(np.float64)
        assert len(features) == 18  # 11 + 7 frames
        reference = PCA(n_components=17, svd_solver="full").fit(features)
        basis = artefact.cameras[camera]
        assert basis.num_samples == 18 and basis.components_with_variance == 17
        np.testing.assert_allclose(basis.mean, reference.mean_, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(basis.explained_variance[:17], reference.explained_variance_, rtol=1e-4)
        signs = np.sign(np.sum(basis.components[:17] * reference.components_, axis=1))
        np.testing.assert_allclose(basis.components[:17] * signs[:, None], reference.components_, atol=1e-3)
        assert np.all(basis.components[17:] == 0)


def test_the_metadata_records_each_suite_its_folder_and_frames(roots, tmp_path):
    _, object_root, goal_root = roots
    assert fit(tmp_path / "fe", object_root, goal_root, stride=2) == 0
    record = json.loads((tmp_path / "fe" / METADATA_FILE).read_text())["fit"]
    assert record["suites"] == ["libero_object", "libero_goal"]
    assert record["hdf5_roots"] == [str(object_root.resolve()), str(goal_root.resolve())]
    assert record["by_suite"] == {
        "libero_object": {"hdf5_root": str(object_root.resolve()), "num_files": 1, "num_demos": 2, "num_frames": 11,
                          "num_frames_fitted": 6},  # every 2nd frame of 6 and of 5: 3 + 3
        "libero_goal": {"hdf5_root": str(goal_root.resolve()), "num_files": 1, "num_demos": 1, "num_frames": 7,
                        "num_frames_fitted": 4},
    }
    assert (record["num_demos"], record["num_frames"], record["num_frames_fitted"]) == (3, 18, 10)


def test_a_missing_empty_or_doubled_suite_folder_is_named(roots, tmp_path, capsys):
    one, object_root, goal_root = roots
    cases = []
    assert fit(tmp_path / "a", object_root, suites="libero_object,libero_goal") != 0
    cases.append(("libero_goal", "does not exist"))
    (tmp_path / "empty" / "libero_goal").mkdir(parents=True)
    assert fit(tmp_path / "b", object_root, tmp_path / "empty") != 0
    cases.append((str(tmp_path / "empty" / "libero_goal"), "no *_demo.hdf5 files"))
    assert fit(tmp_path / "c", one, goal_root) != 0
    cases.append((str(goal_root / "libero_goal"), "in several hdf5 roots"))
    assert fit(tmp_path / "d", object_root, goal_root, tmp_path / "absent") != 0
    cases.append((str(tmp_path / "absent"), "hdf5 root does not exist"))
    (tmp_path / "other" / "libero_10").mkdir(parents=True)
    assert fit(tmp_path / "e", object_root, goal_root, tmp_path / "other") != 0
    cases.append((str(tmp_path / "other"), "holds none of the suites"))
    errors = capsys.readouterr().err.strip().splitlines()
    assert len(errors) == len(cases)
    for error, (folder, message) in zip(errors, cases, strict=True):
        assert folder in error and message in error, error
    assert not any((tmp_path / name).exists() for name in "abcde")
