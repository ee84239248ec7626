"""A demonstration dataset's statistics from its hdf5 files (`python -m research.dataset_stats`)."""

import json

import h5py
import numpy as np

from research import dataset_stats


def _write_task(path, demos: list[np.ndarray]) -> None:
    with h5py.File(path, "w") as f:
        for k, actions in enumerate(demos):
            f.create_dataset(f"data/demo_{k}/actions", data=actions)


def _actions(steps: int, still: list[int], grip_changes: list[int] = ()) -> np.ndarray:
    """`steps` actions moving at 0.5 but at the `still` steps; the gripper -1, flipped to +1 from each change on."""
    actions = np.zeros((steps, 7))
    actions[:, 0] = 0.5
    actions[still, :6] = 0.0
    actions[:, 6] = -1.0
    for step in grip_changes:
        actions[step:, 6] *= -1
    return actions


def test_counts_lengths_and_openvla_no_op_steps(tmp_path):
    # Task a: a still first step (a no-op: OpenVLA's filter judges the first step by its motion alone), a still step
    # where the gripper changes (not a no-op) and a still step after it (a no-op). Task b: one 250-step demonstration.
    _write_task(tmp_path / "task_a_demo.hdf5", [_actions(10, still=[0, 4, 5], grip_changes=[4]), _actions(30, [])])
    _write_task(tmp_path / "task_b_demo.hdf5", [_actions(250, still=[1, 2])])
    out = tmp_path / "stats.json"

    assert dataset_stats.main([str(tmp_path), "--label", "toy", "--out", str(out)]) == 0

    stats = json.loads(out.read_text())
    assert stats["dataset"] == "toy"
    assert stats["per_task"]["task_a"] == {"demos": 2, "steps_mean": 20.0, "steps_max": 30, "longer_than_200": 0,
                                           "noop_fraction": round(2 / 40, 4)}
    assert stats["per_task"]["task_b"]["longer_than_200"] == 1
    assert stats["per_task"]["task_b"]["noop_fraction"] == round(2 / 250, 4)
    everything = stats["all"]
    assert (everything["demos"], everything["steps_min"], everything["steps_max"]) == (3, 10, 250)
    assert everything["noop_fraction"] == round(4 / 290, 4)
    assert "OpenVLA" in everything["noop_rule"]


def test_a_folder_without_demonstrations_is_refused_naming_it(tmp_path, capsys):
    out = tmp_path / "stats.json"
    assert dataset_stats.main([str(tmp_path), "--label", "x", "--out", str(out)]) == 2
    assert str(tmp_path) in capsys.readouterr().err
    assert not out.exists()


def test_a_file_without_the_robomimic_layout_is_refused_naming_it(tmp_path, capsys):
    with h5py.File(tmp_path / "bad_demo.hdf5", "w") as f:
        f.create_dataset("actions", data=np.zeros((3, 7)))
    out = tmp_path / "stats.json"
    assert dataset_stats.main([str(tmp_path), "--label", "x", "--out", str(out)]) == 2
    assert "bad_demo.hdf5" in capsys.readouterr().err
    assert not out.exists()
