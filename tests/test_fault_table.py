"""`python -m lerobot_predvla.report.faults`: the fault-injection table of docs/reliability.md."""

import json

from lerobot_predvla.report.faults import main


def eval_info(path, successes, faults):
    path.mkdir()
    info = {"per_task": [{"task_id": 0, "metrics": {"successes": successes}}], "overall": {}}
    if faults is not None:
        info["predvla_faults"] = faults
    (path / "eval_info.json").write_text(json.dumps(info))
    return path / "eval_info.json"


def faults(vision, proprio, injected=None):
    policy = {"observation.vision_features": vision, "observation.state": proprio, "fallback_actions": 0}
    return {"faulted_episodes": [], "nonfinite_actions": 0, "policy": policy,
            **({} if injected is None else {"injected": injected})}


def test_rows_are_sorted_clean_first_and_bad_files_are_named(tmp_path, capsys):
    noisy = eval_info(tmp_path / "a", [True, False, True],
                      faults(5, 7, {"rate": 0.2, "mode": "nan", "seed": 0, "vision": 6, "proprio": 7, "steps": 30}))
    clean = eval_info(tmp_path / "b", [True, True, True], faults(0, 0))
    assert main([str(noisy), str(clean)]) == 0
    rows = capsys.readouterr().out.splitlines()[2:]
    assert rows == ["| 0 | - | 3/3 | 0 | 0 | 0 | 0 / 0 | 0 / 0 |", "| 0.2 | nan | 2/3 | 0 | 0 | 0 | 6 / 7 | 5 / 7 |"]
    plain = eval_info(tmp_path / "c", [True], None)  # a lerobot-eval run without predvla_libero
    assert main([str(plain)]) == 2
    assert f"{plain}: no `predvla_faults` section of a predvla_libero run" in capsys.readouterr().err
