"""Any LeRobot dataset in: fit, convert, train with the real `lerobot-train`, act from raw frames, evaluate.

Datasets are built with LeRobot's own API in two layouts (LIBERO community: state 8, action 7, cameras
`image`/`image2`; SO-101: state 6, action 6, cameras `front`/`wrist`, 30 fps). The front end uses
`--vision-weights random` (ImageNet weights cannot be downloaded offline) at 64 px to keep the tests fast.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.constants import OBS_STATE
from lerobot_factory import LIBERO_COMMUNITY, SO101, Layout, make_dataset
from libero_factory import BIN, run, run_cli

from lerobot_predvla.columns import FRONTEND_META_DIR, OBS_LANGUAGE_FEATURES, OBS_VISION_FEATURES
from lerobot_predvla.frontend import FrozenFrontend
from lerobot_predvla.policies.predvla.configuration_predvla import PredVLAConfig

SOUP = "pick up the alphabet soup and place it in the basket"  # libero_object task 0
MILK = "pick up the milk and place it in the basket"
EPISODES = {
    "libero": (LIBERO_COMMUNITY, [(SOUP, 7), (MILK, 6), (SOUP, 5)]),
    "so101": (SO101, [("pick up the red cube", 6), ("put the cube in the box", 5), ("pick up the red cube", 4)]),
}
SIZES = {"libero": (8, 7, 2), "so101": (6, 6, 2)}  # state, action, cameras


def fit(source: Path, out: Path, *extra: str) -> int:
    return run_cli(["fit-frontend", "--dataset-root", str(source), "--vision-weights", "random", "--image-size", "64",
                    "--out", str(out), *extra])


def convert(source: Path, frontend: Path, out: Path, *extra: str) -> int:
    return run_cli(["convert", "--dataset-root", str(source), "--frontend", str(frontend), "--out", str(out), *extra])


def prepare(name: str, root: Path) -> dict:
    """Source dataset, fitted front end, converted dataset and a 2-step `lerobot-train` checkpoint."""
    layout, episodes = EPISODES[name]
    make_dataset(root / "source", layout, episodes, repo_id=f"local/{name}")
    assert fit(root / "source", root / "frontend") == 0
    assert convert(root / "source", root / "frontend", root / "converted", "--repo-id", f"local/{name}_predvla") == 0
    log = run([str(BIN / "lerobot-train"), "--policy.type=predvla", f"--dataset.repo_id=local/{name}_predvla",
               f"--dataset.root={root / 'converted'}", "--policy.push_to_hub=false", "--policy.device=cpu",
               "--num_workers=0", "--steps=2", "--save_freq=2", "--batch_size=2", "--wandb.enable=false",
               "--policy.sequence_length=8", "--policy.er_window=4", "--policy.er_iterations=2",
               f"--output_dir={root / 'train'}"])
    return {"name": name, "layout": layout, "root": root, "train_log": log,
            "checkpoint": root / "train" / "checkpoints" / "000002" / "pretrained_model"}


@pytest.fixture(scope="module")
def libero_layout(tmp_path_factory) -> dict:
    return prepare("libero", tmp_path_factory.mktemp("libero"))


@pytest.fixture(scope="module")
def so101_layout(tmp_path_factory) -> dict:
    return prepare("so101", tmp_path_factory.mktemp("so101"))


@pytest.fixture(params=["libero_layout", "so101_layout"])
def layout(request) -> dict:
    return request.getfixturevalue(request.param)


def data_table(root: Path) -> pa.Table:
    return pa.concat_tables([pq.read_table(f) for f in sorted((root / "data").glob("*/*.parquet"))])


@pytest.mark.slow  # its fixture trains with lerobot-train
def test_conversion_keeps_every_column_and_adds_the_features(layout):
    root = layout["root"]
    source, converted = data_table(root / "source"), data_table(root / "converted")
    for column in source.column_names:  # images (PNG bytes), state, action, indices: unchanged
        assert converted.column(column).equals(source.column(column)), column
    info = json.loads((root / "converted" / "meta" / "info.json").read_text())
    num_cameras = len(layout["layout"].cameras)
    assert info["features"][OBS_VISION_FEATURES]["shape"] == [96 * num_cameras]
    assert info["features"][OBS_LANGUAGE_FEATURES]["shape"] == [64]
    stats = json.loads((root / "converted" / "meta" / "stats.json").read_text())
    assert len(stats[OBS_VISION_FEATURES]["mean"]) == 96 * num_cameras and OBS_STATE in stats
    assert (root / "converted" / FRONTEND_META_DIR / "frontend.json").is_file()

    # The cached features are the front end's on the frames LeRobotDataset serves.
    frontend = FrozenFrontend.load(root / "frontend", verbose=False)
    assert list(frontend.artefact.cameras) == list(layout["layout"].cameras)
    original = LeRobotDataset(f"local/{layout['name']}", root=root / "source")
    written = LeRobotDataset(f"local/{layout['name']}_predvla", root=root / "converted")
    items = [original[i] for i in range(len(original))]
    images = {key: torch.stack([item[key] for item in items]) for key in frontend.artefact.cameras}
    cached = torch.stack([written[i][OBS_VISION_FEATURES] for i in range(len(written))])
    torch.testing.assert_close(cached, frontend.encode_images(images), rtol=1e-5, atol=1e-5)
    language = torch.stack([written[i][OBS_LANGUAGE_FEATURES] for i in range(len(written))])
    torch.testing.assert_close(language, frontend.encode_instructions([item["task"] for item in items]), rtol=0,
                               atol=0)


@pytest.mark.slow  # its fixture trains with lerobot-train
def test_lerobot_train_takes_the_sizes_from_the_dataset(layout):
    from lerobot_predvla import PredVLAPolicy

    state, action, cameras = SIZES[layout["name"]]
    config = json.loads((layout["checkpoint"] / "config.json").read_text())
    assert (config["proprio_dim"], config["action_dim"], config["num_cameras"]) == (state, action, cameras)
    policy = PredVLAPolicy(PredVLAConfig(proprio_dim=state, action_dim=action, num_cameras=cameras))
    count = sum(p.numel() for p in policy.parameters())
    layout_text = f"{cameras} cameras x 96, state {state}, action {action}, language 64"
    assert f"PredVLA: {count:,} trainable parameters ({layout_text})" in layout["train_log"]


@pytest.mark.slow  # its fixture trains with lerobot-train
def test_acts_from_raw_frames_through_the_checkpoints_processors(layout):
    """As `lerobot-rollout --policy.path=...` calls it: raw uint8 frames, state and task -> robot action."""
    from lerobot.common.control_utils import predict_action
    from lerobot.policies.factory import make_pre_post_processors

    from lerobot_predvla import PredVLAPolicy

    ckpt, root, name = layout["checkpoint"], layout["root"], layout["name"]
    config = PredVLAConfig.from_pretrained(ckpt)
    policy = PredVLAPolicy.from_pretrained(ckpt, config=config)
    pre, post = make_pre_post_processors(config, pretrained_path=str(ckpt))
    original = LeRobotDataset(f"local/{name}", root=root / "source")
    written = LeRobotDataset(f"local/{name}_predvla", root=root / "converted")
    steps = range(5)
    raw_actions = []
    for i in steps:
        item = original[i]
        observation = {key: np.round(item[key].permute(1, 2, 0).numpy() * 255).astype(np.uint8)
                       for key in layout["layout"].cameras}
        observation[OBS_STATE] = item[OBS_STATE].numpy()
        raw_actions.append(predict_action(observation, policy, torch.device("cpu"), pre, post, use_amp=False,
                                          task=item["task"], robot_type=layout["layout"].robot_type))
    raw_actions = torch.cat(raw_actions)
    assert raw_actions.shape == (len(steps), SIZES[name][1]) and torch.isfinite(raw_actions).all()

    # The same steps from the converted dataset's cached columns give the same actions.
    policy.reset()
    pre.reset()
    cached_actions = []
    with torch.inference_mode():
        for i in steps:
            item = written[i]
            batch = {k: item[k] for k in (OBS_VISION_FEATURES, OBS_LANGUAGE_FEATURES, OBS_STATE)}
            cached_actions.append(post(policy.select_action(pre({**batch, "task": item["task"]}))))
    torch.testing.assert_close(raw_actions, torch.cat(cached_actions), rtol=1e-4, atol=1e-4)


@pytest.mark.slow  # its fixture trains with lerobot-train
def test_cameras_flag_chooses_the_streams(layout, tmp_path):
    root = layout["root"]
    wrist = list(layout["layout"].cameras)[1]
    assert fit(root / "source", tmp_path / "frontend", "--cameras", wrist) == 0
    assert list(FrozenFrontend.load(tmp_path / "frontend", verbose=False).artefact.cameras) == [wrist]
    assert convert(root / "source", tmp_path / "frontend", tmp_path / "converted") == 0
    info = json.loads((tmp_path / "converted" / "meta" / "info.json").read_text())
    assert info["features"][OBS_VISION_FEATURES]["shape"] == [96]


def test_video_dataset_keeps_its_videos(tmp_path, capsys):
    """Cameras stored as videos (LeRobot's default): decoded through LeRobotDataset, copied byte for byte."""
    layout = replace(SO101, cameras={"observation.images.front": (24, 32)})
    make_dataset(tmp_path / "source", layout, [("pick", 6), ("place", 5)], use_videos=True)
    assert fit(tmp_path / "source", tmp_path / "frontend") == 0
    assert convert(tmp_path / "source", tmp_path / "frontend", tmp_path / "converted") == 0
    videos = sorted((tmp_path / "source" / "videos").rglob("*.mp4"))
    assert videos
    for video in videos:
        assert (tmp_path / "converted" / video.relative_to(tmp_path / "source")).read_bytes() == video.read_bytes()
    original = LeRobotDataset("local/tiny", root=tmp_path / "source")
    written = LeRobotDataset("local/tiny", root=tmp_path / "converted")
    frontend = FrozenFrontend.load(tmp_path / "frontend", verbose=False)
    images = {"observation.images.front": torch.stack([original[i]["observation.images.front"] for i in range(11)])}
    cached = torch.stack([written[i][OBS_VISION_FEATURES] for i in range(11)])
    torch.testing.assert_close(cached, frontend.encode_images(images), rtol=1e-5, atol=1e-5)

    # An episode whose video segment is shorter than the episode is rejected.
    _edit_parquet(next((tmp_path / "source" / "meta" / "episodes").glob("*/*.parquet")),
                  "videos/observation.images.front/to_timestamp", 1, 0.25)
    capsys.readouterr()
    _assert_rejected(convert(tmp_path / "source", tmp_path / "frontend", tmp_path / "again"), capsys,
                     tmp_path / "again", ["episode 1", "key 'observation.images.front'", "length mismatch"])


# ----- bad input: one line naming dataset, episode and key; exit code 2; nothing written -------------------------
def _edit_parquet(path: Path, column: str, row: int, value) -> None:
    table = pq.read_table(path)
    values = table.column(column).to_pylist()
    values[row] = value
    index = table.column_names.index(column)
    pq.write_table(table.set_column(index, column, pa.array(values, type=table.schema.field(column).type)), path)


def _length_mismatch(source: Path) -> None:
    _edit_parquet(next((source / "meta" / "episodes").glob("*/*.parquet")), "length", 1, 99)


def _non_finite_state(source: Path) -> None:
    path = next((source / "data").glob("*/*.parquet"))
    state = pq.read_table(path).column("observation.state").to_pylist()[8]
    _edit_parquet(path, "observation.state", 8, [float("nan"), *state[1:]])


BAD_SOURCES = {
    # case: (layout change, episodes, edit of the written dataset, expected fragments)
    "no image feature": (replace(SO101, cameras={}), None, None, ["key 'features'", "no image or video feature"]),
    "empty task": (SO101, [("pick", 3), ("  ", 4)], None, ["episode 1", "key 'task'", "empty"]),
    "length mismatch": (SO101, None, _length_mismatch, ["episode 1", "key 'length'", "length mismatch"]),
    "non-finite state": (SO101, None, _non_finite_state, ["episode 1", "key 'observation.state'", "non-finite"]),
}


def _assert_rejected(code: int, capsys, out: Path, fragments: list[str]) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and all(f in err[0] for f in fragments), err
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")]  # no partial directory


@pytest.mark.parametrize("case", list(BAD_SOURCES))
def test_bad_dataset_is_rejected(case, tmp_path, capsys):
    source_layout, episodes, edit, fragments = BAD_SOURCES[case]
    make_dataset(tmp_path / "source", source_layout, episodes or [("pick", 5), ("place", 4)])
    if edit is not None:
        edit(tmp_path / "source")
    capsys.readouterr()
    code = fit(tmp_path / "source", tmp_path / "frontend")
    _assert_rejected(code, capsys, tmp_path / "frontend", [f"dataset {tmp_path / 'source'}", *fragments])


def test_bad_conversion_requests_are_rejected(tmp_path, capsys):
    layout: Layout = SO101
    make_dataset(tmp_path / "source", layout, [("pick", 5), ("place", 4)])
    assert fit(tmp_path / "source", tmp_path / "frontend") == 0
    out = tmp_path / "converted"
    capsys.readouterr()
    _assert_rejected(convert(tmp_path / "source", tmp_path / "frontend", out, "--cameras", "observation.images.top"),
                     capsys, out, ["key 'observation.images.top'", "no such camera", "observation.images.front"])
    _assert_rejected(convert(tmp_path / "source", tmp_path / "frontend", out, "--cameras", "observation.images.front"),
                     capsys, out, ["fitted on cameras", "observation.images.wrist"])
    _assert_rejected(convert(tmp_path / "missing", tmp_path / "frontend", out), capsys, out,
                     ["key 'meta/info.json'", "not a LeRobot dataset"])
    assert not (tmp_path / "missing").exists()
    code = run_cli(["convert", "--dataset-repo-id", "lerobot/libero_object_image", "--frontend",
                    str(tmp_path / "frontend"), "--out", str(out)])
    _assert_rejected(code, capsys, out, ["dataset lerobot/libero_object_image", "Hugging Face Hub", "--dataset-root"])
    # Converting twice is refused, and an existing output is never touched.
    assert convert(tmp_path / "source", tmp_path / "frontend", out) == 0
    capsys.readouterr()
    assert convert(out, tmp_path / "frontend", tmp_path / "twice") == 2
    assert "already has PredVLA's cached features" in capsys.readouterr().err
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    assert convert(tmp_path / "source", tmp_path / "frontend", out) == 2
    assert "already exists" in capsys.readouterr().err
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before


def test_summary_and_progress(tmp_path, capsys):
    make_dataset(tmp_path / "source", SO101, [("pick", 5), ("place", 4), ("pick", 3)])
    assert fit(tmp_path / "source", tmp_path / "frontend") == 0
    captured = capsys.readouterr()
    assert "fitted front end on 3 episodes / 12 frames" in captured.out and "encoding frames" in captured.err
    assert convert(tmp_path / "source", tmp_path / "frontend", tmp_path / "converted") == 0
    captured = capsys.readouterr()
    assert f"wrote {tmp_path / 'converted'}: 3 episodes, 12 frames, 2 tasks" in captured.out
    assert "converting" in captured.err


# ----- LIBERO: LeRobot's own `lerobot-eval --env.type=libero` with its unchanged 8-dim state processor ----------
def test_state_processor_follows_the_policys_state():
    from lerobot.envs import make_env_pre_post_processors
    from lerobot.envs.configs import LiberoEnv
    from lerobot.processor.env_processor import LiberoProcessorStep

    from lerobot_predvla.sims.libero.env_config import PredVLALiberoEnv, PredVLALiberoProcessorStep

    env = LiberoEnv(task="libero_object", task_ids=[0])
    steps = {dim: make_env_pre_post_processors(env, PredVLAConfig(proprio_dim=dim))[0].steps for dim in (8, 9)}
    assert [type(s) for s in steps[9]] == [PredVLALiberoProcessorStep]
    assert [type(s) for s in steps[8]] == [LiberoProcessorStep]  # LeRobot's own, unchanged
    with pytest.raises(ValueError, match="6-dim observation.state"):
        make_env_pre_post_processors(env, PredVLAConfig(proprio_dim=6))
    with pytest.raises(ValueError, match="--env.type=libero"):
        make_env_pre_post_processors(PredVLALiberoEnv(task="libero_object", task_ids=[0]), PredVLAConfig(proprio_dim=8))


@pytest.mark.slow
@pytest.mark.simulator
def test_lerobot_eval_on_libero_with_lerobots_state(libero_layout, tmp_path):
    """A policy trained on the community layout (state 8) runs in the real simulator under `lerobot-eval`."""
    log = run([str(BIN / "lerobot-eval"), f"--policy.path={libero_layout['checkpoint']}", "--env.type=libero",
               "--env.task=libero_object", "--env.task_ids=[0]", "--env.episode_length=6",
               "--env.observation_height=128", "--env.observation_width=128", "--eval.n_episodes=1",
               "--eval.batch_size=1", "--eval.use_async_envs=false", "--policy.device=cpu",
               f"--output_dir={tmp_path}"])
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1, log[-2000:]
    assert 0.0 <= info["overall"]["pc_success"] <= 100.0


@pytest.mark.slow  # its fixture trains with lerobot-train
def test_model_card_describes_the_robots_own_layout(so101_layout):
    from lerobot_predvla.hub.card import render_card
    from lerobot_predvla.hub.upload import publishable_files

    card = render_card(publishable_files(so101_layout["checkpoint"]), "me/predvla_so101", None)
    assert "| `observation.state` | (6,) | the training dataset's `observation.state` (state) |" in card
    assert "| `action` | (6,) | the training dataset's `action` (action) |" in card
    assert "joint positions (7)" not in card
    source = so101_layout["root"] / "source"
    assert f"| fitted on | dataset: {source}; demonstrations: 3; frames: 15; instructions: 2 |" in card
