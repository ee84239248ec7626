"""`predvla convert`: LIBERO hdf5 -> LeRobot v3.0 dataset with cached features, and its rejections."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.utils import preprocess_observation
from lerobot.processor.env_processor import LiberoProcessorStep
from libero_factory import RAW_TOP_ROWS, run_cli, write_libero_file

from lerobot_predvla.columns import HDF5_CAMERAS, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.data import conversion
from lerobot_predvla.data.features_only import features_only_copy
from lerobot_predvla.data.libero_hdf5 import LiberoDataError, scan_file
from lerobot_predvla.frontend import FrontendArtefact, FrozenFrontend
from lerobot_predvla.frontend.preprocessing import libero_hdf5_to_lerobot

SOUP = "pick up the alphabet soup and place it in the basket"
MILK = "pick up the milk and place it in the basket"
SUITE = "libero_object"
# (file, instruction, demo lengths, seed); episodes follow file name order, then demo number.
FILES = [("a_soup_demo.hdf5", SOUP, [6, 5], 1), ("b_soup_again_demo.hdf5", SOUP, [4], 2),
         ("c_milk_demo.hdf5", MILK, [5], 3)]
EPISODES = [(file, f"demo_{i}", n, text) for file, text, lengths, _ in FILES for i, n in enumerate(lengths)]
CAMERA_HDF5 = {"observation.images.image": "obs/agentview_rgb", "observation.images.image2": "obs/eye_in_hand_rgb"}



@pytest.fixture(scope="module")
def libero(tmp_path_factory) -> tuple[Path, dict]:
    """The hdf5 root and the arrays written, keyed by (file, demo)."""
    root = tmp_path_factory.mktemp("libero")
    arrays = {}
    for file, text, lengths, seed in FILES:
        for demo, data in write_libero_file(root / SUITE / file, text, lengths, seed=seed).items():
            arrays[file, demo] = data
    return root, arrays


@pytest.fixture(scope="module")
def frontend_dir(libero, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fe") / "frontend"
    argv = ["fit-frontend", "--hdf5-root", str(libero[0]), "--suites", SUITE, "--vision-weights", "random",
            "--out", str(out)]
    assert run_cli(argv) == 0
    return out


@pytest.fixture(scope="module")
def frontend(frontend_dir) -> FrozenFrontend:
    return FrozenFrontend.load(frontend_dir, verbose=False)


def convert(libero_root: Path, frontend_dir: Path, out: Path, *extra: str) -> int:
    return run_cli(["convert", "--hdf5-root", str(libero_root), "--suite", SUITE, "--frontend", str(frontend_dir),
                    "--out", str(out), *extra])


@pytest.fixture(scope="module")
def png_dataset(libero, frontend_dir, tmp_path_factory) -> LeRobotDataset:
    out = tmp_path_factory.mktemp("datasets") / "libero_object_png"
    assert convert(libero[0], frontend_dir, out, "--image-storage", "png", "--repo-id", "local/obj") == 0
    return LeRobotDataset("local/obj", root=out)


def episode_frames(dataset: LeRobotDataset) -> list[list[dict]]:
    frames = [dataset[i] for i in range(len(dataset))]
    return [[f for f in frames if f["episode_index"] == e] for e in range(dataset.meta.total_episodes)]


def test_dataset_layout(png_dataset):
    meta = png_dataset.meta
    assert meta.fps == 20 and meta.robot_type == "panda"
    assert meta.total_episodes == len(EPISODES) and meta.total_frames == sum(e[2] for e in EPISODES)
    assert meta.total_tasks == 2
    shapes = {camera: (128, 128, 3) for camera in HDF5_CAMERAS} | {
        "observation.state": (9,), "action": (7,), OBS_VISION_FEATURES: (192,), OBS_LANGUAGE_FEATURES: (64,)}
    for key, shape in shapes.items():
        assert tuple(meta.features[key]["shape"]) == shape
        assert meta.features[key]["dtype"] == ("image" if key in HDF5_CAMERAS else "float32")
    lengths = [n for _, _, n, _ in EPISODES]
    assert list(meta.episodes["length"]) == lengths
    assert list(meta.episodes["dataset_from_index"]) == list(np.cumsum([0, *lengths[:-1]]))
    assert list(meta.episodes["dataset_to_index"]) == list(np.cumsum(lengths))
    assert [tasks for tasks in meta.episodes["tasks"]] == [[text] for *_, text in EPISODES]
    assert json.loads((png_dataset.root / conversion.FRONTEND_META_DIR / "frontend.json").read_text())[
        "vision"]["weights"]["source"] == "random"


def test_frames_match_hdf5_and_front_end(png_dataset, libero, frontend):
    _, arrays = libero
    task_index = {}
    for (file, demo, n, text), frames in zip(EPISODES, episode_frames(png_dataset), strict=True):
        data = arrays[file, demo]
        assert len(frames) == n
        assert [int(f["frame_index"]) for f in frames] == list(range(n))
        torch.testing.assert_close(torch.stack([f["timestamp"] for f in frames]), torch.arange(n) / 20.0)
        assert {f["task"] for f in frames} == {text}
        assert len({int(f["task_index"]) for f in frames}) == 1
        assert task_index.setdefault(text, int(frames[0]["task_index"])) == int(frames[0]["task_index"])
        state = np.concatenate([data["obs/joint_states"], data["obs/gripper_states"]], axis=1)
        assert torch.equal(torch.stack([f["observation.state"] for f in frames]),
                           torch.from_numpy(state.astype(np.float32)))
        assert torch.equal(torch.stack([f["action"] for f in frames]),
                           torch.from_numpy(data["actions"].astype(np.float32)))
        # Images are stored rotated as LeRobot's LIBERO env delivers them (PNG is lossless).
        oriented = {cam: libero_hdf5_to_lerobot(data[key]) for cam, key in CAMERA_HDF5.items()}
        stored = {cam: torch.stack([f[cam] for f in frames]) for cam in HDF5_CAMERAS}
        for cam in HDF5_CAMERAS:
            assert stored[cam].dtype == torch.float32
            assert torch.equal(stored[cam], torch.from_numpy(oriented[cam]).permute(0, 3, 1, 2).float() / 255)
        # Cached features equal a direct recomputation, from the hdf5 pixels and from the dataset images.
        cached = torch.stack([f[OBS_VISION_FEATURES] for f in frames])
        assert torch.equal(cached, frontend.encode_images(oriented))
        assert torch.equal(cached, frontend.encode_images(stored))
        language = torch.stack([f[OBS_LANGUAGE_FEATURES] for f in frames])
        assert torch.equal(language, frontend.encode_instructions([text] * n))
    assert len(task_index) == 2


def test_identical_instructions_share_features_across_files(png_dataset):
    by_task = {}
    for i in range(len(png_dataset)):
        item = png_dataset[i]
        by_task.setdefault(item["task"], []).append(item[OBS_LANGUAGE_FEATURES])
    for features in by_task.values():
        assert all(torch.equal(f, features[0]) for f in features)
    assert not torch.equal(by_task[SOUP][0], by_task[MILK][0])


def test_simulator_route_gives_the_cached_features(png_dataset, libero, frontend):
    """Raw renders through LeRobot's env preprocessing + LiberoProcessorStep, one frame at a time."""
    _, arrays = libero
    data = arrays["c_milk_demo.hdf5", "demo_0"]
    first = int(png_dataset.meta.episodes["dataset_from_index"][3])
    for t in range(3):
        obs = preprocess_observation({"pixels": {k.split(".")[-1]: data[v][t] for k, v in CAMERA_HDF5.items()}})
        obs = LiberoProcessorStep().observation(obs)
        live = frontend.encode_images({cam: obs[cam] for cam in HDF5_CAMERAS})[0]
        cached = png_dataset[first + t][OBS_VISION_FEATURES]
        # Only the batch size differs (1 here, the whole episode when caching); measured 0 on x86 CPUs.
        assert (live - cached).norm() / cached.norm() < 5e-3


def test_video_storage(libero, frontend_dir, png_dataset, tmp_path):
    out = tmp_path / "libero_object_video"
    assert convert(libero[0], frontend_dir, out) == 0
    video = LeRobotDataset("local/libero_object", root=out)
    assert video.meta.features["observation.images.image"]["dtype"] == "video"
    assert video.meta.total_frames == png_dataset.meta.total_frames
    for i in (0, len(video) - 1):
        v, p = video[i], png_dataset[i]
        assert torch.equal(v[OBS_VISION_FEATURES], p[OBS_VISION_FEATURES])  # Computed from the hdf5 pixels.
        for cam in HDF5_CAMERAS:
            assert v[cam].shape == (3, 128, 128) and (v[cam] - p[cam]).abs().mean() < 0.05  # Lossy AV1.
            red_band = v[cam][:, -RAW_TOP_ROWS + 1 :]  # The raw top band ends up at the bottom.
            assert red_band[0].mean() > 0.8 and red_band[1:].mean() < 0.2


def test_summary_and_progress(libero, frontend_dir, tmp_path, capsys):
    assert convert(libero[0], frontend_dir, tmp_path / "ds", "--image-storage", "png") == 0
    captured = capsys.readouterr()
    assert "4 episodes, 20 frames, 2 tasks in" in captured.out and "frames/s" in captured.out
    assert "converting" in captured.err  # tqdm bar.


def test_demos_are_read_in_numeric_order(tmp_path):
    path = tmp_path / "many_demo.hdf5"
    write_libero_file(path, SOUP, [1] * 11, size=8)
    assert [ref.demo for ref in scan_file(path)] == [f"demo_{i}" for i in range(11)]


def _delete(key):
    def mutate(f):
        del f[key]
    return mutate


def _replace(key, value_fn):
    def mutate(f):
        value = value_fn(f[key][()])
        del f[key]
        f.create_dataset(key, data=value)
    return mutate


def _poison(index: tuple[int, int], value: float):
    def poisoned(a: np.ndarray) -> np.ndarray:
        a = a.astype(np.float64)
        a[index] = value
        return a
    return poisoned


def _not_libero(path: Path):
    path.unlink()
    with h5py.File(path, "w") as f:
        f.create_dataset("weights", data=np.zeros(3))


def _truncate(path: Path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


BAD_HDF5 = {
    "missing key": (_delete("data/demo_1/obs/eye_in_hand_rgb"), ["demo_1", "obs/eye_in_hand_rgb", "missing key"]),
    "missing actions": (_delete("data/demo_0/actions"), ["demo_0", "'actions'", "missing key"]),
    "length mismatch": (_replace("data/demo_1/actions", lambda a: a[:-1]),
                        ["demo_1", "obs/joint_states", "length mismatch"]),
    "image length mismatch": (_replace("data/demo_0/obs/agentview_rgb", lambda a: a[:-2]),
                              ["demo_0", "obs/agentview_rgb", "length mismatch"]),
    "float images": (_replace("data/demo_0/obs/agentview_rgb", lambda a: a.astype(np.float32)),
                     ["demo_0", "obs/agentview_rgb", "uint8"]),
    "wrong state width": (_replace("data/demo_0/obs/joint_states", lambda a: a[:, :6]),
                          ["demo_0", "obs/joint_states", "expected (N, 7)"]),
    "no problem_info": (lambda f: f["data"].attrs.__delitem__("problem_info"), ["problem_info", "not a LIBERO"]),
    "no demos": (lambda f: [f["data"].__delitem__(k) for k in list(f["data"])], ["no demonstrations"]),
    "nan action": (_replace("data/demo_1/actions", _poison((2, 4), np.nan)),
                   ["demo_1", "key 'actions'", "non-finite value nan at index [2, 4]"]),
    "inf joint state": (_replace("data/demo_0/obs/joint_states", _poison((0, 6), np.inf)),
                        ["demo_0", "key 'obs/joint_states'", "non-finite value inf at index [0, 6]"]),
    "nan gripper state": (_replace("data/demo_1/obs/gripper_states", _poison((3, 1), -np.inf)),
                          ["demo_1", "key 'obs/gripper_states'", "non-finite value -inf at index [3, 1]"]),
}
BAD_FILES = {"not LIBERO": (_not_libero, ["not a LIBERO", "'data'"]), "garbage": (
    lambda p: p.write_bytes(b"\x00garbage" * 100), ["corrupt"]), "truncated": (_truncate, ["corrupt"])}


def _assert_rejected(code: int, capsys, out: Path, fragments: list[str]):
    err = capsys.readouterr().err
    assert code == 2, err
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    assert not out.exists()
    assert not out.parent.exists() or not any(out.parent.iterdir())  # No staging directory left behind.


@pytest.mark.parametrize("case", [*BAD_HDF5, *BAD_FILES, "empty demo"])
def test_bad_input_is_rejected(case, frontend_dir, tmp_path, capsys):
    root = tmp_path / "root"
    write_libero_file(root / SUITE / "a_good_demo.hdf5", SOUP, [3], seed=5, size=32)
    bad = root / SUITE / "b_bad_demo.hdf5"
    write_libero_file(bad, MILK, [3, 0] if case == "empty demo" else [3, 4], seed=6, size=32)
    if case == "empty demo":
        fragments = ["demo_1", "'actions'", "empty demonstration"]
    elif case in BAD_HDF5:
        mutate, fragments = BAD_HDF5[case]
        with h5py.File(bad, "a") as f:
            mutate(f)
    else:
        mutate, fragments = BAD_FILES[case]
        mutate(bad)
    out = tmp_path / "out" / "ds"
    _assert_rejected(convert(root, frontend_dir, out), capsys, out, [str(bad), *fragments])


def test_frontend_dims_mismatch_is_rejected(libero, frontend_dir, tmp_path, capsys):
    out = tmp_path / "out" / "ds"
    code = convert(libero[0], frontend_dir, out, "--vision-dim-per-camera", "48")
    fragments = [str(frontend_dir / "frontend.json"), "vision.cameras[observation.images.image].n_components",
                 "is 96, requested 48"]
    _assert_rejected(code, capsys, out, fragments)
    code = convert(libero[0], frontend_dir.parent / "nowhere", out)
    _assert_rejected(code, capsys, out, ["frontend.json: missing"])


def test_failure_mid_conversion_leaves_nothing(libero, frontend_dir, tmp_path, capsys, monkeypatch):
    real_read = conversion.read_demo
    calls = []

    def failing_read(ref, *args, **kwargs):
        calls.append(ref)
        if len(calls) == 3:
            raise LiberoDataError(ref.file, "cannot read data (simulated bad chunk)", ref.demo, "obs/agentview_rgb")
        return real_read(ref, *args, **kwargs)

    monkeypatch.setattr(conversion, "read_demo", failing_read)
    out = tmp_path / "out" / "ds"
    code = convert(libero[0], frontend_dir, out)
    _assert_rejected(code, capsys, out, ["b_soup_again_demo.hdf5", "demo_0", "simulated bad chunk"])


def test_nonfinite_features_stop_the_conversion(libero, frontend_dir, tmp_path, capsys, monkeypatch):
    real_encode = FrozenFrontend.encode_images
    calls = []

    def encode_with_nan(self, images):
        features = real_encode(self, images)
        calls.append(len(features))
        if len(calls) == 2:
            features[1, 7] = float("nan")
        return features

    monkeypatch.setattr(FrozenFrontend, "encode_images", encode_with_nan)
    out = tmp_path / "out" / "ds"
    code = convert(libero[0], frontend_dir, out)
    fragments = ["a_soup_demo.hdf5", "demo_1", f"key '{OBS_VISION_FEATURES}'", "non-finite value nan at index [1, 7]"]
    _assert_rejected(code, capsys, out, fragments)


def test_existing_output_is_not_touched(libero, frontend_dir, tmp_path, capsys):
    out = tmp_path / "ds"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert convert(libero[0], frontend_dir, out) == 2
    assert "already exists" in capsys.readouterr().err and (out / "keep.txt").read_text() == "mine"


def test_artefact_travels_with_dataset(png_dataset, frontend_dir):
    copy = FrontendArtefact.load(png_dataset.root / conversion.FRONTEND_META_DIR)
    assert copy.metadata() == FrontendArtefact.load(frontend_dir).metadata()


def test_conversion_without_frames_is_the_features_only_copy(png_dataset, libero, frontend_dir, tmp_path):
    """`--image-storage none` writes what `predvla features-only` keeps of a converted dataset (every column
    but the cameras, value for value), and the front-end artefact, without the cameras."""
    out = tmp_path / "features"
    assert convert(libero[0], frontend_dir, out, "--image-storage", "none", "--repo-id", "local/obj") == 0
    direct = LeRobotDataset("local/obj", root=out)
    copy = features_only_copy(png_dataset.root, tmp_path / "copy", repo_id="local/obj")
    assert not direct.meta.camera_keys and set(direct.meta.features) == set(copy.meta.features)
    assert len(direct) == len(copy) == len(png_dataset)
    for i in range(len(direct)):
        a, b = direct[i], copy[i]
        assert a.keys() == b.keys()
        for key, value in a.items():
            assert torch.equal(value, b[key]) if isinstance(value, torch.Tensor) else value == b[key], key
    assert (out / conversion.FRONTEND_META_DIR / "frontend.json").read_bytes() == (
        tmp_path / "copy" / conversion.FRONTEND_META_DIR / "frontend.json").read_bytes()
