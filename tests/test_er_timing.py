"""`python -m research.er_timing`: error regression's lift step against the exact open loop's, and the outcomes, on
hand-made traces."""

import json

import numpy as np
import pytest
from trace_factory import raw_actions, trace_checkpoint, write_trace

from research import er_timing as et
from research.er_correction import load_trace_run


def lifting(close_at: int, lift_at: int, steps: int = 14) -> np.ndarray:
    """Raw actions that close the gripper at `close_at`, descend until `lift_at` and rise from it; the hand also
    rises once before the close (an approach's move, not a lift)."""
    actions = raw_actions([(0.1, 0.0)], close_at=close_at, steps=steps)
    actions[:, et.Z] = np.where(np.arange(steps) >= lift_at, 1.0, -0.3)
    actions[1, et.Z] = 1.0
    return actions


def write_outcomes(path, successes: list[bool], task_id: int = 3) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"per_task": [{"task_group": "libero_object", "task_id": task_id,
                                              "metrics": {"successes": successes}}]}))


@pytest.fixture
def traces(tmp_path):
    """Six starts: three lift a step before the open loop and fail, three lift with it and succeed."""
    checkpoint = trace_checkpoint(tmp_path / "ckpt")
    write_trace(tmp_path / "ol", checkpoint, [lifting(4, 8)], open_loop=True)
    write_trace(tmp_path / "er", checkpoint, [lifting(4, 7), lifting(4, 8), lifting(4, 7), lifting(4, 8),
                                              lifting(4, 7), lifting(4, 9)], omp_num_threads="1")
    write_outcomes(tmp_path / "er" / "eval" / "eval_info.json", [True] * 6)  # the trace's own, shorter episodes
    write_outcomes(tmp_path / "full" / "eval_info.json", [False, True, False, True, False, True, True, False])
    return tmp_path


def test_the_lift_is_the_first_rise_after_the_close():
    assert et.lift_step(lifting(4, 9), close=4) == 9
    assert et.lift_step(lifting(4, 9), close=None) is None
    no_lift = lifting(4, 99)
    no_lift[1, et.Z] = 1.0
    assert et.lift_step(no_lift, close=4) is None


def test_early_lifts_that_fail_are_found_and_tested(traces, capsys):
    out = traces / "out"
    argv = ["--trace", str(traces / "er"), "--open-loop", str(traces / "ol"),
            "--outcomes", str(traces / "full" / "eval_info.json"), "--test-states", "0-5", "--out", str(out)]
    assert et.main(argv) == 0
    report = json.loads((out / et.REPORT_JSON).read_text())
    assert report["open_loop"] == {"close": 4, "lift": 8}
    assert [e["lift"] for e in report["episodes"]] == [7, 8, 7, 8, 7, 9]
    assert [e["success"] for e in report["episodes"]] == [False, True, False, True, False, True]
    test = report["tests"]["test starts"]
    assert test["table"] == [[3, 0], [0, 3]]  # early: failed, succeeded; not early: failed, succeeded
    assert test["p"] == pytest.approx(0.05)  # one arrangement of 20 puts all three failures on the early lifts
    assert (out / et.FIGURE).stat().st_size > 0
    text = capsys.readouterr().out
    assert "| test starts | 0-5 | 6 | 3 / 0 | 0 / 3 |" in text
    # the commands that remake the traces, with the thread count the error-regression trace ran with
    assert f"\nOMP_NUM_THREADS=1 predvla trace {traces / 'er'} " in text and f"\npredvla trace {traces / 'ol'} " in text

    half = et.early_lift_test([et.EpisodeTiming(s, 4, lift, ok) for s, (lift, ok)
                               in enumerate([(7, False), (7, True), (8, False), (8, True)])], 8, [0, 1, 2, 3])
    assert half["table"] == [[1, 1], [1, 1]] and half["p"] > 0.5


def test_without_outcomes_the_traces_own_evaluation_counts(traces):
    assert et.main(["--trace", str(traces / "er"), "--open-loop", str(traces / "ol"),
                         "--out", str(traces / "out")]) == 0
    report = json.loads((traces / "out" / et.REPORT_JSON).read_text())
    assert all(e["success"] for e in report["episodes"]) and list(report["tests"]) == ["all traced starts"]


def test_bad_input_is_named_and_nothing_is_written(traces, capsys):
    checkpoint = traces / "ckpt"
    write_trace(traces / "ol_flat", checkpoint, [lifting(4, 99)], open_loop=True)
    write_outcomes(traces / "short" / "eval_info.json", [True, False])
    cases = {
        ("--test-states", "0-9"): "were not traced",
        ("--test-states", "five"): "expected A-B",
        ("--outcomes", str(traces / "short" / "eval_info.json")): "the outcomes name 2",
        ("--outcomes", str(traces / "missing.json")): "eval_info.json",
        ("--open-loop", str(traces / "ol_flat")): "no lift to time against",
        ("--open-loop", str(traces / "er")): "did not run with --policy.er_iterations=0",
    }
    for extra, message in cases.items():
        args = {"--trace": str(traces / "er"), "--open-loop": str(traces / "ol"), "--out": str(traces / "out")}
        args.update(dict([extra]))
        assert et.main([*[x for kv in args.items() for x in kv]]) == 2, extra
        assert message in capsys.readouterr().err, extra
    assert not (traces / "out").exists()


def test_randomised_resets_are_timed_and_named_as_such(tmp_path, capsys):
    """A trace on randomised resets (`--env.init_states=false`) is timed like one on the official init states; the
    report names its starts, and er_correction, which runs the expert from official init states, still refuses it."""
    checkpoint = trace_checkpoint(tmp_path / "ckpt")
    write_trace(tmp_path / "ol", checkpoint, [lifting(4, 8)], open_loop=True, init_states="false")
    write_trace(tmp_path / "er", checkpoint, [lifting(4, 7), lifting(4, 9)], init_states="false")
    trace = json.loads((tmp_path / "er" / "trace.json").read_text())
    trace["eval_args"].append("--seed=3000")
    (tmp_path / "er" / "trace.json").write_text(json.dumps(trace))
    write_outcomes(tmp_path / "er" / "eval" / "eval_info.json", [False, True])
    assert et.main(["--trace", str(tmp_path / "er"), "--open-loop", str(tmp_path / "ol"),
                    "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / et.REPORT_JSON).read_text())
    assert report["starts"] == "randomised resets of seed 3000"
    assert report["tests"]["all traced starts"]["table"] == [[1, 0], [0, 1]]
    text = capsys.readouterr().out
    assert "| set | randomised resets of seed 3000 |" in text and "| reset | close |" in text
    with pytest.raises(ValueError, match="official init states"):
        load_trace_run(tmp_path / "er")
