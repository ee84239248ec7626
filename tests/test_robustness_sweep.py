"""Sweep entries with shifted objects or LIBERO-PRO / LIBERO-plus variants, and the report's robustness table (fake
lerobot-eval, fake records)."""

import json
from pathlib import Path

import pytest
from sweep_factory import FakeLeRobot, arg, sweep_file

from lerobot_predvla.report import write_report
from lerobot_predvla.report.formatting import MISSING
from lerobot_predvla.report.robustness import robustness_figure, robustness_table
from lerobot_predvla.sweep import Runner, Sweep, SweepError
from lerobot_predvla.utils.io import atomic_write_json

POLICY = "PredVLA, exact open loop"
CONFIGS = [
    {"name": "predvla", "group": "main"},
    {"name": "shift0", "group": "robustness", "label": POLICY, "checkpoint_from": "predvla",
     "eval_overrides": {"er_iterations": 0}, "object_shift": {"cm": 0}},
    {"name": "shift4", "group": "robustness", "label": POLICY, "checkpoint_from": "predvla",
     "eval_overrides": {"er_iterations": 0}, "object_shift": {"cm": 4, "pattern": "ring", "directions": 20}},
    {"name": "pro_x01", "group": "robustness", "label": POLICY, "checkpoint_from": "predvla",
     "eval_overrides": {"er_iterations": 0}, "variant": "pro_temp_x0.1"},
]


class FakeShiftedEval(FakeLeRobot):
    """lerobot-eval that also writes `predvla_shifts` with one unsettled episode (episode 3 of the first task it
    evaluates) when objects are shifted."""

    def __call__(self, command: list[str], log: Path) -> int:
        code = super().__call__(command, log)
        cm = arg(command, "env.object_shift_cm")
        if any(c.endswith("lerobot-eval") for c in command) and cm not in (None, "0"):
            path = Path(arg(command, "output_dir")) / "eval_info.json"
            info = json.loads(path.read_text())
            task = json.loads(arg(command, "env.task_ids") or "[0]")[0]
            info["predvla_shifts"] = {"episodes": [], "unsettled_episodes": [{"task_id": task, "episode_ix": 3}]}
            path.write_text(json.dumps(info))
        return code


def test_shift_and_variant_entries_become_env_flags_records_and_their_own_table(tmp_path):
    sweep = Sweep.load(sweep_file(tmp_path, seeds=[0], suites=["libero_object"], configs=CONFIGS))
    fake = FakeShiftedEval()
    outcome = Runner(sweep, tmp_path / "runs", execute=fake).run(progress=False)
    assert not outcome["failed"] and len(outcome["done"]) == 4
    evals = {arg(c, "output_dir").split("/eval/")[1].split("/")[0]: c for c in fake.commands if arg(c, "seed")
             and any(w.endswith("lerobot-eval") for w in c)}
    assert "--env.object_shift_cm=4" in evals["shift4"] and "--env.object_shift_pattern=ring" in evals["shift4"]
    assert "--env.object_shift_directions=20" in evals["shift4"] and "--env.object_shift_cm=0" in evals["shift0"]
    assert arg(evals["pro_x01"], "env.task") == "libero_object_pro_temp_x0.1"
    assert not any(a.startswith("--env.object_shift") for a in evals["pro_x01"] + evals["predvla"])
    record = json.loads((tmp_path / "runs/records/shift4/libero_object/seed0.json").read_text())
    assert record["object_shift"] == {"cm": 4, "pattern": "ring", "directions": 20}
    assert record["shift_unsettled"] == 1 and record["variant"] is None
    assert record["shift_unsettled_episodes"] == {"0": [3], "1": [], "2": []}
    assert json.loads((tmp_path / "runs/records/pro_x01/libero_object/seed0.json").read_text())["variant"] == \
        "pro_temp_x0.1"

    summary = write_report(tmp_path / "runs", tmp_path / "report")
    report = (tmp_path / "report" / "report.md").read_text()
    section = report.split("## Robustness")[1].split("\n## ")[0]
    # fake successes: task t, seed 0 succeeds in 50 - t of 50 episodes (tasks 0-2): 147/150; without the unsettled
    # episode (task 0's episode 3, a success) 146/149
    assert (f"| {POLICY} | object | 98.0 (147/150) | 98.0 (147/150), 1 unsettled; settled 98.0 (146/149) | "
            "98.0 (147/150) |") in section
    assert "| Policy | Suite | 0 cm | 4 cm | pro_temp_x0.1 |" in section
    assert summary["figures"]["robustness"] == "success_vs_shift.png"
    assert (tmp_path / "report" / "success_vs_shift.png").is_file()
    main = report.split("## Main results")[1].split("\n## ")[0]
    assert POLICY not in main  # robustness runs are left out of the main table


def _record(label: str, suite: str, cm: float | None, successes: int, variant: str | None = None, **extra) -> dict:
    return {"config": f"{label}_{cm}_{variant}", "label": label, "suite": suite, "seed": 0,
            "object_shift": None if cm is None else {"cm": cm}, "variant": variant,
            "tasks": {"0": {"successes": successes, "episodes": 20}}, **extra}


def test_robustness_table_pools_seeds_orders_conditions_and_leaves_other_runs_out(tmp_path):
    records = [
        _record("BC", "libero_object", 4, 10, shift_unsettled=2),  # a record that kept the count alone
        _record("BC", "libero_object", 4, 5, seed=1, shift_unsettled=0),
        _record("BC", "libero_object", 0, 20, shift_unsettled=0),
        _record("BC", "libero_object", None, 12, variant="plus_language_3"),
        _record("PredVLA", "libero_object", 2, 8),
        {**_record("main", "libero_object", None, 20)},  # neither shifted nor a variant: not in the table
    ]
    text = robustness_table(records)
    assert text.splitlines()[0] == "| Policy | Suite | 0 cm | 2 cm | 4 cm | plus_language_3 |"
    assert (f"| BC | object | 100.0 (20/20) | {MISSING} | 37.5 (15/40), 2 unsettled; settled n/a | 60.0 (12/20) "
            "|") in text
    assert "| PredVLA | object | — | 40.0 (8/20); settled n/a | — | — |" in text  # neither count nor episodes
    assert "main" not in text
    assert robustness_table([_record("main", "libero_object", None, 20)]) is None
    assert robustness_figure(records, tmp_path / "f.png") and (tmp_path / "f.png").is_file()
    assert robustness_figure([_record("P", "libero_object", 2, 8)], tmp_path / "g.png")  # one point: a marker
    assert not robustness_figure([_record("P", "libero_object", None, 8, variant="pro_swap")], tmp_path / "h.png")


def _blind_replay(root: Path, cm: float, successes: list[int]) -> Path:
    """A `predvla blind-replay` report folder's per-task files: two episodes per task, the object shifted `cm`."""
    folder = root / f"shift{cm:g}"
    for task, won in enumerate(successes):
        settings = {"states": [0, 1], **({"shift": {"object_cm": cm, "pattern": "ring"}} if cm else {})}
        atomic_write_json(folder / "tasks" / "libero_object" / f"task{2 * task}.json",
                          {"settings": settings, "plans": {"state0": {"successes": won, "episodes": 2}}})
    return folder


def test_blind_replays_are_a_reference_row_and_a_dashed_line_of_the_robustness_section(tmp_path):
    from lerobot_predvla.report.results import ReportError
    from lerobot_predvla.report.robustness import BLIND_LABEL, blind_line

    line = blind_line([_blind_replay(tmp_path, 4.0, [1, 0]), _blind_replay(tmp_path, 0.0, [2, 1])])
    assert line == {"libero_object": [(0.0, 3, 4), (4.0, 1, 4)]}  # by shift, whatever the order given
    records = [_record("P", "libero_object", 4, 8)]
    text = robustness_table(records, blind=line)
    assert text.splitlines()[0] == "| Policy | Suite | 0 cm | 4 cm |"
    assert f"| {BLIND_LABEL} | object | 75.0 (3/4) | 25.0 (1/4) |" in text
    assert robustness_figure(records, tmp_path / "f.png", line)
    mixed = _blind_replay(tmp_path / "mixed", 2.0, [1])
    atomic_write_json(mixed / "tasks" / "libero_object" / "task9.json",
                      {"settings": {"states": [0]}, "plans": {"state0": {"successes": 0, "episodes": 1}}})
    with pytest.raises(ReportError, match="different object shifts"):
        blind_line([mixed])
    with pytest.raises(ReportError, match=r"--blind-replay .*empty: no `predvla blind-replay` per-task results"):
        blind_line([tmp_path / "empty"])


@pytest.mark.parametrize("change, message", [
    ({"object_shift": {"cm": 4, "angle": 3}}, "unknown keys \\['angle'\\]"),
    ({"object_shift": {"cm": -1}}, "must be >= 0"),
    ({"object_shift": {"cm": 2, "pattern": "spiral"}}, "object_shift_pattern"),
    ({"object_shift": {"pattern": "ring"}}, "expected a mapping with `cm`"),
    ({"object_shift": {"cm": 2}, "init_states": False}, "init_states: true"),
    ({"variant": "temp_x0.1"}, "not a LIBERO-PRO or LIBERO-plus variant name"),
])
def test_bad_shift_or_variant_entries_name_the_configuration_and_the_problem(tmp_path, change, message):
    configs = [{"name": "predvla"}, {"name": "bad", "group": "robustness", "checkpoint_from": "predvla", **change}]
    with pytest.raises(SweepError, match=f"configuration bad: .*{message}"):
        Sweep.load(sweep_file(tmp_path, configs=configs))


def test_the_looking_sweep_measures_every_policy_under_every_condition_paired_with_the_open_loop(tmp_path):
    """configs/sweeps/libero_object_looking.yaml (docs/research/looking.md): the committed trainings' configurations as
    their sweeps trained them, 5 policies x (6 shifts + 8 variants) on the same 20 starts, each paired with PredVLA's
    exact open loop of the same condition."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    looking, table2, reading = (Sweep.load(sweeps / f) for f in ("libero_object_looking.yaml",
                                                                 "libero_object_table2.yaml",
                                                                 "libero_object_reading_full.yaml"))
    for name, twin in (("B1", table2.configs["B1"]), ("B2", table2.configs["B2"]),
                       ("predvla_reading", reading.configs["predvla_reading"])):
        ours = looking.configs[name]
        assert (ours.policy, ours.steps, ours.lr_sweep) == (twin.policy, twin.steps, twin.lr_sweep), name
    s = looking.settings
    assert (s.n_episodes, s.eval_tasks, s.episode_length, s.seeds) == (4, [0, 2, 4, 6, 8], 600, [0])
    rows: dict[str, set] = {}
    for spec in looking.configs.values():
        assert spec.group == "robustness" and spec.init_states and spec.n_episodes is None
        shift = spec.object_shift or {}
        assert (shift.get("pattern"), shift.get("directions")) in ((None, None), ("ring", 4))
        rows.setdefault(spec.label, set()).add(spec.variant or shift["cm"])
        if spec.compare_to is not None:
            reference = looking.configs[spec.compare_to]
            assert (reference.object_shift, reference.variant) == (spec.object_shift, spec.variant), spec.name
            assert reference.eval_overrides == {"er_iterations": 0}, spec.name
    conditions = {0, 1, 2, 3, 4, 6, "pro_temp_x0.1", "pro_temp_x0.2", "pro_temp_y0.1", "pro_temp_y0.2", "pro_swap",
                  "pro_lan", "pro_with_yellow_book", "plus_language_1"}
    assert len(rows) == 5 and all(row == conditions for row in rows.values())
    assert len(looking.configs) == 5 * len(conditions)


def _write_run(runs: Path, config: str, successes: list[bool], **record) -> None:
    """One seed-0 run of task 0: its eval_info.json and its record (official init states, seed 0)."""
    part = runs / "eval" / config / "libero_object" / "seed0" / "task0"
    atomic_write_json(part / "eval_info.json", {"per_task": [
        {"task_group": "libero_object", "task_id": 0, "metrics": {"successes": successes}}]})
    atomic_write_json(runs / "records" / config / "libero_object" / "seed0.json", {
        "config": config, "suite": "libero_object", "seed": 0, "group": "robustness", "eval_seed": 0,
        "init_states": True, "n_episodes_per_task": len(successes), "episode_length": 600, "variant": None,
        "object_shift": None, "tasks": {"0": {"successes": sum(successes), "episodes": len(successes)}}, **record})


def test_the_robustness_section_repeats_cells_and_paired_comparisons_without_the_unsettled_episodes(tmp_path):
    """docs/research/looking.md: success per cell and error regression against exact open loop per condition, paired
    episode by episode (both / only one / neither, sign test), once over all episodes and once over those whose
    shifted object settled in both runs; "n/a" where a record kept only the unsettled count."""
    from lerobot_predvla.report import sign_test

    runs = tmp_path / "runs"
    er, ol = [True, True, False, True, True, False], [True, False, False, False, False, True]
    shift4 = {"object_shift": {"cm": 4}}
    _write_run(runs, "ol4", ol, label="OL", **shift4, shift_unsettled=1, shift_unsettled_episodes={"0": [1]})
    _write_run(runs, "er4", er, label="ER", compare_to="ol4", **shift4, shift_unsettled=1,
               shift_unsettled_episodes={"0": [4]})
    shift2 = {"object_shift": {"cm": 2}, "shift_unsettled": 1}  # records that kept the count alone
    _write_run(runs, "ol2", ol, label="OL", **shift2)
    _write_run(runs, "er2", er, label="ER", compare_to="ol2", **shift2)
    for name in ("zr4", "cr4", "mr4"):  # more policies at one condition: their rows by configuration name
        _write_run(runs, name, ol, label=name.upper(), compare_to="ol4", **shift4)
    _write_run(runs, "ol_swap", ol, label="OL", variant="pro_swap")
    _write_run(runs, "er_swap", er, label="ER", compare_to="ol_swap", variant="pro_swap")
    summary = write_report(runs, tmp_path / "report")
    # All pairs: both 1 (episode 0), only ER 3 (1, 3, 4), only OL 1 (5), neither 1 (2). Without episodes 1 and 4
    # (unsettled in one run each): both 1, only ER 1 (3), only OL 1 (5), neither 1.
    pairs = summary["configs"]["er4"]["episodes"]["libero_object"]
    assert (pairs["pairs"], pairs["only"], pairs["only_against"]) == (6, 3, 1)
    assert pairs["settled"] == {"pairs": 4, "successes": 2, "against_successes": 2, "only": 1, "only_against": 1,
                                "sign_test_p": 1.0}
    assert summary["configs"]["er2"]["episodes"]["libero_object"]["settled"] is None
    assert "settled" not in summary["configs"]["er_swap"]["episodes"]["libero_object"]  # nothing was shifted
    section = (tmp_path / "report" / "report.md").read_text().split("## Robustness")[1].split("\n## ")[0]
    assert "| Policy | Suite | 2 cm | 4 cm | pro_swap |" in section
    # ER at 4 cm: 4/6; its settled episodes 0, 1, 2, 3, 5: 3/5. OL: 2/6; settled 0, 2, 3, 4, 5: 2/5.
    assert ("| ER | object | 66.7 (4/6), 1 unsettled; settled n/a | 66.7 (4/6), 1 unsettled; settled 60.0 (3/5) | "
            "66.7 (4/6) |") in section
    assert "| OL | object | 33.3 (2/6), 1 unsettled; settled n/a | 33.3 (2/6), 1 unsettled; settled 40.0 (2/5) |" \
        in section
    p = f"{sign_test(3, 1):.3g}"
    assert f"| ER | OL | object | 4 cm | 6 | 1 / 3 / 1 / 1 | {p} | 4 | 1 / 1 / 1 / 1 | 1 |" in section
    assert f"| ER | OL | object | 2 cm | 6 | 1 / 3 / 1 / 1 | {p} | n/a | n/a | n/a |" in section
    assert f"| ER | OL | object | pro_swap | 6 | 1 / 3 / 1 / 1 | {p} | 6 | 1 / 3 / 1 / 1 | {p} |" in section
    rows = [line for line in section.splitlines() if line.startswith("| ER | OL |")]
    assert [row.split(" | ")[3] for row in rows] == ["2 cm", "4 cm", "pro_swap"]  # shifts by distance, then variants
    at4 = [line.split(" | ")[0] for line in section.splitlines() if "| OL | object | 4 cm |" in line]
    assert at4 == ["| CR4", "| ER", "| MR4", "| ZR4"]  # not in the order of a set of names


def test_an_extended_record_keeps_the_unsettled_episodes_of_each_call_or_says_they_are_unknown(tmp_path):
    """A record extended by a later call for other tasks (`--eval-tasks`) keeps each task's unsettled episodes; an
    earlier record that kept only their count (written before the indices were recorded) leaves them unknown (None)
    unless its count was 0."""
    configs = [CONFIGS[0], CONFIGS[2]]

    def run(tasks: list[int]) -> dict:
        sweep = Sweep.load(sweep_file(tmp_path, seeds=[0], suites=["libero_object"], configs=configs,
                                      eval={"device": "cpu", "tasks": tasks, "n_episodes": 4}))
        assert not Runner(sweep, tmp_path / "runs", execute=FakeShiftedEval()).run(progress=False)["failed"]
        return json.loads(path.read_text())

    path = tmp_path / "runs/records/shift4/libero_object/seed0.json"
    assert run([0])["shift_unsettled_episodes"] == {"0": [3]}
    record = run([1, 2])
    assert record["shift_unsettled_episodes"] == {"0": [3], "1": [3], "2": [3]} and record["shift_unsettled"] == 3
    atomic_write_json(path, {**record, "shift_unsettled_episodes": None, "tasks": {"0": record["tasks"]["0"]},
                             "shift_unsettled": 1})  # as written before: the count alone
    record = run([1])
    assert record["shift_unsettled_episodes"] is None and record["shift_unsettled"] == 2
    atomic_write_json(path, {**record, "tasks": {"0": record["tasks"]["0"]}, "shift_unsettled": 0})
    assert run([2])["shift_unsettled_episodes"] == {"0": [], "2": [3]}
