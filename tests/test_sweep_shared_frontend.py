"""A sweep's data stage with one front end shared by several suites (`data.<suite>.frontend_from`): every suite's
demonstrations first, one joint fit, then each suite's conversion."""

import json

import pytest
import yaml
from sweep_factory import FakeData, sweep_file

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.sweep import Runner, Sweep, SweepError

SHARED = ["libero_object", "libero_spatial"]


def shared_data(**changes) -> dict:
    entry = {"frontend": "out/frontend", "per_task": 2, "tasks": [0, 1], "vision_weights": "random",
             "frontend_from": SHARED, "image_storage": "none"}
    return {"libero_object": {**entry, "hdf5": "out/object_hdf5"},  # two places: the fit reads both
            "libero_spatial": {**entry, "hdf5": "out/hdf5", **changes}}


def program(command: list[str]) -> list[str]:
    return command[command.index("lerobot_predvla.cli.main") + 1:]


def test_a_shared_front_end_is_fitted_once_on_every_suites_demonstrations(tmp_path, monkeypatch):
    from lerobot_predvla.cli import sweep as sweep_cli

    path = sweep_file(tmp_path, seeds=[0], data=shared_data())
    fake = FakeData()
    monkeypatch.setattr(sweep_cli, "Runner", lambda sweep, runs_dir, **kw: Runner(sweep, runs_dir, execute=fake, **kw))
    assert predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--data-only"]) == 0
    steps = [program(c) for c in fake.commands]
    assert [(s[0], s[s.index("--suite") + 1] if "--suite" in s else None) for s in steps] == [
        ("demos", "libero_object"), ("demos", "libero_spatial"), ("fit-frontend", None), ("convert", "libero_object"),
        ("convert", "libero_spatial")]
    fit = steps[2]
    roots = [fit[i + 1] for i, a in enumerate(fit) if a == "--hdf5-root"]
    assert roots == [str(tmp_path / "out/object_hdf5"), str(tmp_path / "out/hdf5")]
    assert fit[fit.index("--suites") + 1] == "libero_object,libero_spatial"
    assert {s[s.index("--frontend") + 1] for s in steps[3:]} == {str(tmp_path / "out/frontend")}
    # The first suite's data stage made the other's demonstrations and the fit; the second only converted.
    stages = {s: list(json.loads((tmp_path / f"runs/data/{s}.json").read_text())) for s in SHARED}
    assert stages == {"libero_object": ["demos", "demos.libero_spatial", "frontend", "convert"],
                      "libero_spatial": ["convert"]}


def test_the_dry_run_lists_the_shared_stages_once(tmp_path, capsys):
    path = sweep_file(tmp_path, seeds=[0], data=shared_data(), configs=[{"name": "predvla", "group": "main"}])
    assert predvla_main(["sweep", str(path), "--runs-dir", str(tmp_path / "runs"), "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert sum(" fit-frontend " in line for line in lines) == 1
    assert sum(" demos " in line for line in lines) == 2 and sum(" convert " in line for line in lines) == 2


def test_once_fitted_a_suite_makes_only_its_own_demonstrations(tmp_path):
    runner = Runner(Sweep.load(sweep_file(tmp_path, seeds=[0], data=shared_data())), tmp_path / "runs",
                    execute=FakeData())
    assert runner.make_data("libero_spatial")
    for hdf5 in ("object_hdf5", "hdf5"):  # e.g. a fresh disk beside the fitted front end: no demonstrations
        (tmp_path / "out" / hdf5).rename(tmp_path / hdf5)
    stages = [stage for stage, _ in runner.data_commands("libero_object")]
    assert stages == ["demos", "convert"]


@pytest.mark.parametrize(("change", "message"), [
    ({"frontend_from": ["libero_spatial"]}, "fitted on"),
    ({"frontend_from": ["libero_spatial", "libero_object"]}, "in one order"),
    ({"frontend_from": ["libero_object", "libero_goal"]}, "data.libero_spatial.frontend_from must include"),
    ({"frontend_from": SHARED + ["libero_goal"]}, "which have no `data` entry"),
    ({"frontend_from": SHARED + ["libero_100"]}, "unknown suites ['libero_100']"),
    ({"frontend_from": []}, "non-empty list"),
    ({"frontend_from": None}, "fitted on"),  # a second suite naming the folder without the list
    ({"frame_stride": 2}, "frame_stride differs"),
    ({"vision_weights": "imagenet"}, "vision_weights differs"),
])
def test_a_shared_front_end_must_be_named_alike_by_all_its_suites(tmp_path, change, message):
    with pytest.raises(SweepError, match="data") as error:
        Sweep.load(sweep_file(tmp_path, seeds=[0], data=shared_data(**change)))
    assert message in str(error.value)


def test_suites_with_their_own_front_ends_are_unchanged(tmp_path):
    data = {s: {"hdf5": "out/hdf5", "frontend": f"out/{s}_frontend", "vision_weights": "random"} for s in SHARED}
    runner = Runner(Sweep.load(sweep_file(tmp_path, seeds=[0], data=data)), tmp_path / "runs")
    fit = dict(runner.data_commands("libero_spatial"))["frontend"]
    assert program(fit)[1:5] == ["--hdf5-root", str(tmp_path / "out/hdf5"), "--suites", "libero_spatial"]
    same_folder = yaml.safe_load(yaml.safe_dump(data))
    same_folder["libero_spatial"]["frontend"] = "out/libero_object_frontend"
    with pytest.raises(SweepError, match="fitted on"):  # one folder, two separate fits: one would overwrite the other
        Sweep.load(sweep_file(tmp_path, seeds=[0], data=same_folder))
