"""`python -m research.er_correction`: error regression's correction before the grasp against the expert's
deviation. The arithmetic on hand-made traces; the expert's approach on the simulator (physics only)."""

import numpy as np
import pytest
from trace_factory import raw_actions, trace_checkpoint, write_trace

from research import er_correction as ec


@pytest.fixture
def checkpoint(tmp_path):
    return trace_checkpoint(tmp_path / "ckpt")


def test_approach_sums_the_xy_actions_before_the_gripper_closes():
    total, step = ec.approach(raw_actions([(0.5, -0.25)], close_at=4))
    assert step == 4 and np.allclose(total, [2.0, -1.0])
    total, step = ec.approach(raw_actions([(0.1, 0.2)], close_at=99, steps=5))  # never closes: the whole sequence
    assert step is None and np.allclose(total, [0.5, 1.0])


def test_traces_are_unnormalised_and_a_correction_that_follows_the_expert_has_slope_one(tmp_path, checkpoint):
    deviations = np.array([[0.4, -0.2], [-0.4, 0.1], [0.0, 0.1], [0.2, 0.3], [-0.2, -0.3]])
    open_loop = raw_actions([(0.1, 0.2)], close_at=6)
    bias = np.array([0.05, -0.1])
    er_episodes = []
    for d in deviations:  # error regression adds bias + half of each start's deviation on step 0
        a = open_loop.copy()
        a[0, :2] += bias + 0.5 * d
        er_episodes.append(a)
    write_trace(tmp_path / "er", checkpoint, er_episodes)
    write_trace(tmp_path / "ol", checkpoint, [open_loop], open_loop=True)
    er, ol = ec.load_trace_run(tmp_path / "er"), ec.load_trace_run(tmp_path / "ol")
    assert er.task_id == 3 and not er.open_loop and ol.open_loop
    assert np.allclose(er.actions[1], er_episodes[1], atol=1e-6)  # float32 statistics

    ol_sum = ec.approach(open_loop)[0]
    expert = [{"state": s, "sum_xy": (ol_sum + 0.3 + d).tolist(), "close_step": 5, "success": True}
              for s, d in enumerate(deviations)]  # the expert's mean approach sits 0.3 beyond the open loop's
    task = ec.task_correction(er, ol, expert)
    assert np.allclose(task.expert_deviation, deviations - deviations.mean(axis=0))
    assert np.allclose(task.correction, bias + 0.5 * deviations)
    assert np.allclose(task.open_loop_offset, -0.3 - deviations.mean(axis=0))
    summary = ec.summarise([task])
    for axis in "xy":
        assert summary["axes"][axis]["slope"] == pytest.approx(0.5)
        assert summary["axes"][axis]["r2"] == pytest.approx(1.0)
    assert np.allclose(summary["per_task"]["3"]["correction_mean"], bias + 0.5 * deviations.mean(axis=0))
    assert np.allclose(summary["per_task"]["3"]["slope"], 0.5) and np.allclose(summary["per_task"]["3"]["r"], 1.0)

    report = ec.write_report(tmp_path / "out", [task], {3: expert}, ["python -m research.er_correction ..."])
    assert (tmp_path / "out" / ec.FIGURE).stat().st_size > 0
    assert report["summary"]["episodes"] == 5 and "| 3 |" in (tmp_path / "out" / ec.REPORT_MD).read_text()


def test_a_shared_bias_does_not_follow_the_expert(tmp_path, checkpoint):
    deviations = np.array([[0.4, -0.2], [-0.4, 0.1], [0.0, 0.1]])
    open_loop = raw_actions([(0.1, 0.2)], close_at=6)
    shifted = open_loop.copy()
    shifted[0, :2] += [0.3, 0.3]
    write_trace(tmp_path / "er", checkpoint, [shifted] * 3)
    write_trace(tmp_path / "ol", checkpoint, [open_loop], open_loop=True)
    expert = [{"state": s, "sum_xy": d.tolist(), "close_step": 5, "success": True} for s, d in enumerate(deviations)]
    task = ec.task_correction(ec.load_trace_run(tmp_path / "er"), ec.load_trace_run(tmp_path / "ol"), expert)
    summary = ec.summarise([task])
    assert np.allclose(summary["per_task"]["3"]["correction_mean"], [0.3, 0.3])
    assert np.allclose(summary["per_task"]["3"]["correction_std"], 0.0)
    assert summary["axes"]["x"]["slope"] == pytest.approx(0.0, abs=1e-9)


def test_the_command_refuses_mismatched_traces_before_running_the_expert(tmp_path, checkpoint, capsys):
    episode = raw_actions([(0.1, 0.2)], close_at=6)
    write_trace(tmp_path / "er", checkpoint, [episode])
    write_trace(tmp_path / "ol_other_task", checkpoint, [episode], task_id=4, open_loop=True)
    write_trace(tmp_path / "er_task4", checkpoint, [episode], task_id=4)
    write_trace(tmp_path / "random", checkpoint, [episode], init_states="false")
    cases = {
        ("--trace", "er", "--open-loop", "ol_other_task"): "no --open-loop trace has that task",
        ("--trace", "er_task4", "--open-loop", "er_task4"): "did not run with --policy.er_iterations=0",
        ("--trace", "ol_other_task", "--open-loop", "ol_other_task"): "exact open loop",
        ("--trace", "random", "--open-loop", "ol_other_task"): "--env.init_states=true",
        ("--trace", "missing", "--open-loop", "ol_other_task"): "trace.json",
    }
    for argv, message in cases.items():
        args = [a if a.startswith("--") else str(tmp_path / a) for a in argv]
        assert ec.main([*args, "--out", str(tmp_path / "out")]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.simulator
def test_the_expert_approach_on_the_simulator():
    """The scripted expert from two official init states of one task: it closes the gripper within its approach,
    and the two starts ask for different approaches."""
    try:
        from lerobot_predvla.sims.libero.env import task_spec

        task_spec("libero_object", 7)
    except (RuntimeError, ImportError) as err:
        pytest.fail(f"LIBERO is not installed: run `make libero` ({err})")
    rows = ec.expert_approaches("libero_object", 7, [0, 1], cap=300)
    assert [r["state"] for r in rows] == [0, 1]
    for row in rows:
        assert row["success"] and 20 < row["close_step"] < 120
        assert np.all(np.isfinite(row["sum_xy"]))
    assert not np.allclose(rows[0]["sum_xy"], rows[1]["sum_xy"])
