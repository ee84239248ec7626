"""`python -m research.dataset_pairs`: the same cells of two datasets' sweeps paired episode by episode, on
hand-made run records and eval_info.json files."""

import json

from lerobot_predvla.utils.statistics import sign_test
from research import dataset_pairs as dp


def write_run(runs, config: str, successes: dict[int, list[bool]], env: tuple[str, ...] = (), seed: int = 3000) -> None:
    """A run record and one eval_info.json per task, as `predvla sweep` writes them."""
    commands = [["lerobot-eval", f"--seed={seed}", *env, f"--env.task_ids=[{task}]"] for task in successes]
    record = {"config": config, "suite": "libero_object", "seed": 0, "tasks": sorted(successes), "eval_seed": seed,
              "init_states": False, "episode_length": 600, "n_episodes_per_task": 4, "commands": {"eval": commands}}
    path = runs / "records" / config / "libero_object" / "seed0.json"
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(record))
    for task, episodes in successes.items():
        info = runs / "eval" / config / "libero_object" / "seed0" / f"task{task}" / "eval_info.json"
        info.parent.mkdir(parents=True)
        info.write_text(json.dumps({"per_task": [{"task_id": task, "metrics": {"successes": episodes}}]}))


def test_same_cells_pair_on_the_same_starts(tmp_path, capsys):
    d2, d3, out = tmp_path / "d2", tmp_path / "d3", tmp_path / "out"
    t, f = True, False
    write_run(d2, "B1", {2: [t, t, t, f], 3: [t, f, f, f]})
    write_run(d3, "B1", {2: [t, f, t, t], 3: [t, t, t, t]})
    write_run(d2, "B1_shifted", {2: [f, f, f, f]}, env=("--env.object_shift_cm=4",))
    write_run(d3, "B1_shifted", {2: [t, t, t, t]}, env=("--env.object_shift_cm=3",))  # other starts: not paired
    write_run(d3, "B2", {2: [t, t, t, t]})  # only in one sweep: left out
    args = ["--runs", f"D2={d2}", "--runs", f"D3={d3}", "--out", str(out)]
    assert dp.main(args) == 0
    report = json.loads((out / "pairs.json").read_text())
    assert report["datasets"] == ["D2", "D3"]
    assert report["cells"]["B1/libero_object/0"] == {"pairs": 8, "successes": 4, "against_successes": 7, "only": 1,
                                                     "only_against": 4, "sign_test_p": sign_test(1, 4)}
    assert report["cells"]["B1_shifted/libero_object/0"] == "starts differ"
    assert set(report["cells"]) == {"B1/libero_object/0", "B1_shifted/libero_object/0"}
    assert "| B1/libero_object/0 | 8 | 4 / 7 | 1 / 4 | 0.38 |" in (out / "pairs.md").read_text()


def test_bad_arguments_are_named(tmp_path, capsys):
    d2 = tmp_path / "d2"
    write_run(d2, "B1", {2: [True]})
    out = tmp_path / "out"
    assert dp.main(["--runs", f"D2={d2}", "--runs", f"D3={d2}", "--cells", "B9", "--out", str(out)]) == 2
    assert "--cells B9: no run record in both" in capsys.readouterr().err
    assert not out.exists()
    for runs in ([f"D2={d2}"], [f"D2={d2}", f"D2={d2}"], [f"D2={d2}", f"D3={tmp_path / 'none'}"]):
        try:
            dp.main([a for r in runs for a in ("--runs", r)] + ["--out", str(out)])
        except SystemExit as err:
            assert err.code == 2
        else:
            raise AssertionError(f"{runs}: accepted")
    err = capsys.readouterr().err
    assert "give exactly two, with different labels" in err and "no records/ folder" in err
