"""`predvla report` on synthetic run records: aggregates, paired deltas, ladder deltas, missing runs, figures."""

import json
from pathlib import Path

import numpy as np
import pytest

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.report import FIGURES, MISSING, load_summary, write_report
from lerobot_predvla.report.sections import INSPECT_DIR, START_SPREAD_FILE, _relative
from lerobot_predvla.sweep import ConfigSpec
from lerobot_predvla.utils.io import atomic_write_json

SUITES4 = ("libero_spatial", "libero_goal", "libero_object", "libero_10")
SHORT = SUITES4[:3]
SEEDS = (0, 1, 2)
CONFIGS = [
    ConfigSpec("predvla", "main", "PredVLA", paper={"libero_object": [89.24, 6.13]}),
    ConfigSpec("B2", "baseline", "BC-RNN (LSTM)"),
    ConfigSpec("L1", "ladder", "- Online error regression", checkpoint_from="predvla",
               eval_overrides={"er_iterations": 0}, suites=list(SHORT)),
    ConfigSpec("L2", "ladder", "- Predictive coding inference", suites=list(SHORT)),
    ConfigSpec("L3", "ladder", "- Prediction pathway", suites=list(SHORT)),
    ConfigSpec("L2b", "ladder", "L2 + direct visual input", compare_to="L2", branch=True, suites=list(SHORT)),
    ConfigSpec("A4", "ablation", "- Visual error in ER", checkpoint_from="predvla", compare_to="predvla",
               eval_overrides={"er_lambda_v": 0.0}, suites=list(SHORT)),
    ConfigSpec("A5", "ablation", "- Proprioceptive error in ER", checkpoint_from="predvla", compare_to="predvla",
               eval_overrides={"er_lambda_q": 0.0}, suites=list(SHORT)),
    ConfigSpec("A6", "ablation", "- Online ER", checkpoint_from="predvla", compare_to="predvla",
               eval_overrides={"er_iterations": 0}, paper={"libero_object": 78.14}),
    *[ConfigSpec(f"C{ch[0]}{int(a * 100)}", "corruption", f"{ch} alpha={a}", checkpoint_from="predvla",
                 compare_to="predvla", corruption={"channel": ch, "alpha": a, "open_loop": "A6"}, suites=list(SHORT))
      for ch in ("vision", "proprio") for a in (0.25, 0.5)],
]
LEVEL = {"predvla": 80, "B2": 12, "L1": 72, "L2": 60, "L3": 12, "L2b": 48, "A4": 76, "A5": 70, "A6": 72,
         "Cv25": 78, "Cv50": 75, "Cp25": 60, "Cp50": 40}
# Runs left out, as if never run or lost: a whole suite of B2, one seed of A4 and of predvla on long.
LEFT_OUT = {("B2", "libero_10", s) for s in SEEDS} | {("A4", "libero_goal", 2), ("predvla", "libero_10", 1)}


def task_successes(config: str, suite: str, seed: int, task: int) -> int:
    """Deterministic per-task successes out of 20 (suite and seed shift the level; tasks spread around it)."""
    level = LEVEL[config] - 10 * (suite == "libero_10") + 3 * seed - 2 * SUITES4.index(suite)
    return int(np.clip(round((level + 8 * (task - 1.5) * (1 + (config == "A5"))) / 5), 0, 20))


def rate(config: str, suite: str, seed: int) -> float:
    return 100 * sum(task_successes(config, suite, seed, t) for t in range(4)) / 80


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    runs = tmp_path_factory.mktemp("runs")
    planned = []
    for spec in CONFIGS:
        for suite in spec.suites or SUITES4:
            for seed in SEEDS:
                planned.append({"config": spec.name, "suite": suite, "seed": seed})
                if (spec.name, suite, seed) in LEFT_OUT:
                    continue
                atomic_write_json(runs / "records" / spec.name / suite / f"seed{seed}.json", {
                    "config": spec.name, "group": spec.group, "label": spec.label, "suite": suite, "seed": seed,
                    "parameters": 674_276 if spec.name == "B2" else 675_732,
                    "tasks": {str(t): {"successes": task_successes(spec.name, suite, seed, t), "episodes": 20}
                              for t in range(4)},
                    "n_episodes_per_task": 20, "episode_length": 600,
                })
    configs = {}
    for spec in CONFIGS:
        configs[spec.name] = {k: getattr(spec, k) for k in (
            "group", "label", "compare_to", "branch", "corruption", "eval_overrides", "checkpoint_from", "paper")}
    atomic_write_json(runs / "plan.json", {"runs": planned, "configs": configs})
    return runs


@pytest.fixture(scope="module")
def report(runs, tmp_path_factory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("report")
    return write_report(runs, out), out


def test_aggregates_are_mean_and_sample_std_across_seeds(report):
    summary, out = report
    cell = summary["configs"]["predvla"]["suites"]["libero_object"]
    values = [rate("predvla", "libero_object", s) for s in SEEDS]
    assert cell["mean"] == pytest.approx(np.mean(values)) and cell["std"] == pytest.approx(np.std(values, ddof=1))
    assert cell["n"] == cell["planned"] == 3
    means = {s: np.mean([rate("predvla", s, k) for k in SEEDS if ("predvla", s, k) not in LEFT_OUT]) for s in SUITES4}
    assert summary["configs"]["predvla"]["mean3"] == pytest.approx(np.mean([means[s] for s in SHORT]))
    assert summary["configs"]["predvla"]["mean4"] == pytest.approx(np.mean(list(means.values())))
    assert load_summary(out) == json.loads(json.dumps(summary))


def test_paired_deltas_use_matched_seeds_only(report):
    summary, _ = report
    paired = summary["configs"]["A4"]["paired"]["libero_goal"]
    assert paired["n"] == 2 and paired["seeds"] == [0, 1]  # seed 2 of A4 is missing
    expected = np.mean([rate("A4", "libero_goal", s) - rate("predvla", "libero_goal", s) for s in (0, 1)])
    assert paired["delta"] == pytest.approx(expected)
    assert summary["configs"]["A6"]["paired"]["libero_10"]["seeds"] == [0, 2]  # predvla seed 1 missing on long


def test_ladder_deltas_follow_the_chain_and_branches_their_parent(report):
    summary, _ = report
    c = summary["configs"]
    assert c["L1"]["paired_against"] == "predvla" and c["L2"]["paired_against"] == "L1"
    assert c["L3"]["paired_against"] == "L2"  # the side branch L2b does not enter the chain
    assert c["L2b"]["paired_against"] == "L2"
    assert c["L3"]["delta_mean3"] == pytest.approx(c["L3"]["mean3"] - c["L2"]["mean3"])


def test_missing_runs_are_marked_and_listed(report):
    summary, out = report
    text = (out / "report.md").read_text()
    assert summary["configs"]["B2"]["mean4"] is None and summary["configs"]["B2"]["suites"]["libero_10"]["n"] == 0
    assert "— (0/3)" in text  # B2 on long: nothing
    assert "(2/3 seeds)" in text  # predvla on long, A4 on goal: partial
    assert set(summary["missing_runs"]) == {f"{c}/{s}/seed{k}" for c, s, k in LEFT_OUT}
    assert "## Missing runs" in text and "`A4/libero_goal/seed2`" in text


def test_tables_and_figures_in_the_markdown(report):
    summary, out = report
    text = (out / "report.md").read_text()
    for heading in ("## Main results", "## Controlled baselines", "## Ladder", "## Ablations",
                    "## Corrupted observations", "## Trainable parameters vs success"):
        assert heading in text, heading
    assert "| Model | Params | spatial | goal | object | 3-suite mean | long | 4-suite mean |" in text
    assert "| B2 | BC-RNN (LSTM) | 674,276 | 0.998× |" in text
    p = summary["configs"]["A5"]["paired"]["libero_object"]
    assert f"{p['delta']:+.2f} (n=3)" in text
    assert set(summary["figures"]) == set(FIGURES)
    for name in FIGURES.values():
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"]({name})" in text


def test_report_command(runs, tmp_path, capsys):
    assert predvla_main(["report", str(runs), "--out", str(tmp_path / "r")]) == 0
    assert (tmp_path / "r" / "report.md").is_file()
    assert predvla_main(["report", str(tmp_path / "empty"), "--out", str(tmp_path / "r2")]) == 2
    assert "no run records" in capsys.readouterr().err


def test_per_task_tables_figure_and_stage_times(report):
    summary, out = report
    text = (out / "report.md").read_text()
    assert "## Per task: object" in text and FIGURES["tasks"] in summary["figures"].values()
    assert (out / FIGURES["tasks"]).is_file()
    row = next(line for line in text.split("## Per task: object")[1].splitlines() if line.startswith("| B2 |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    expected = [np.mean([100 * task_successes("B2", "libero_object", s, t) / 20 for s in SEEDS]) for t in range(4)]
    assert [float(c) for c in cells[1:5]] == pytest.approx(expected, abs=0.006)
    assert float(cells[5]) == pytest.approx(np.mean([rate("B2", "libero_object", s) for s in SEEDS]), abs=0.006)
    stages = text.split("## Stages: wall time and commands")[1]
    assert "| A4 | libero_goal | 1 |" in stages and "| A4 | libero_goal | 2 |" not in stages  # only what ran


def write_eval_info(path: Path, successes: dict[int, list[bool]]) -> None:
    atomic_write_json(path / "eval_info.json", {"per_task": [
        {"task_group": "libero_object", "task_id": t, "metrics": {"successes": s}} for t, s in successes.items()]})


def write_paired_runs(runs: Path) -> None:
    """Runs `er` and `ol` (compare_to er) of seeds 0-2, tasks 0 and 1, 4 episodes each; seed 2's `ol` started
    from other starts."""
    outcomes = {  # (config, seed) -> per task, per episode
        ("er", 0): {0: [True, True, False, True], 1: [True, False, True, True]},
        ("ol", 0): {0: [True, False, False, False], 1: [False, False, True, True]},
        ("er", 1): {0: [True, True, True, True], 1: [False, False, False, False]},
        ("ol", 1): {0: [True, True, False, True], 1: [False, True, False, False]},
        ("er", 2): {0: [True] * 4, 1: [True] * 4},  # evaluated from other starts: not a pair
        ("ol", 2): {0: [False] * 4, 1: [False] * 4},
    }
    for (config, seed), tasks in outcomes.items():
        for task, successes in tasks.items():  # one eval part per task, as `eval.tasks` sweeps write them
            part = runs / "eval" / config / "libero_object" / f"seed{seed}" / f"task{task}"
            part.mkdir(parents=True)
            write_eval_info(part, {task: successes})
        atomic_write_json(runs / "records" / config / "libero_object" / f"seed{seed}.json", {
            "config": config, "suite": "libero_object", "seed": seed, "group": "main" if config == "er" else "ablation",
            "compare_to": None if config == "er" else "er", "eval_seed": 1000 if (config, seed) == ("ol", 2) else 0,
            "init_states": True, "n_episodes_per_task": 4, "episode_length": 280,
            "tasks": {str(t): {"successes": sum(s), "episodes": len(s)} for t, s in tasks.items()}})


def test_compared_runs_are_paired_episode_by_episode(tmp_path):
    """Discordant episode pairs and the exact sign test, over the seeds whose runs share their starts."""
    from lerobot_predvla.report import sign_test

    runs = tmp_path / "runs"
    write_paired_runs(runs)
    summary = write_report(runs, tmp_path / "report")
    pairs = summary["configs"]["ol"]["episodes"]["libero_object"]
    # seed 0: ol 3 successes, er 6; only ol 0, only er 3 (two on task 0, one on task 1).
    # seed 1: ol 4, er 4; only ol 1 (task 1), only er 1 (task 0). Seed 2 started elsewhere and is left out.
    assert pairs.pop("tasks") == {
        "0": {"pairs": 8, "successes": 4, "against_successes": 7, "only": 0, "only_against": 3},
        "1": {"pairs": 8, "successes": 3, "against_successes": 3, "only": 1, "only_against": 1}}
    assert pairs == {"against": "er", "seeds": [0, 1], "pairs": 16, "successes": 7, "against_successes": 10,
                     "only": 1, "only_against": 4, "sign_test_p": pytest.approx(2 * (1 + 5) / 32)}
    assert "episodes" not in summary["configs"]["er"]
    assert sign_test(1, 3) == pytest.approx(2 * (1 + 4) / 16) and sign_test(0, 0) == 1.0 and sign_test(2, 2) == 1.0
    assert sign_test(5, 1) == pytest.approx(2 * 7 / 64) and sign_test(10, 0) == pytest.approx(2 / 1024)
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Paired episodes" in text and "| ol | er | object | 0, 1 | 16 | 7 / 10 | 1 / 4 | 0.375 |" in text


def test_tasks_apart_count_their_pairs_and_the_other_tasks_pairs_separately(tmp_path, capsys):
    """`--tasks-apart 1`: the pairs of task 1 and of the other tasks (task 0), each with its own sign test, beside
    the pooled count, which is unchanged."""
    runs = tmp_path / "runs"
    write_paired_runs(runs)
    pooled = write_report(runs, tmp_path / "pooled")["configs"]["ol"]["episodes"]["libero_object"]
    summary = write_report(runs, tmp_path / "report", tasks_apart=[1])
    pairs = summary["configs"]["ol"]["episodes"]["libero_object"]
    assert summary["tasks_apart"] == [1] and pairs.pop("apart") == {
        "tasks": {"pairs": 8, "successes": 3, "against_successes": 3, "only": 1, "only_against": 1,
                  "sign_test_p": 1.0},
        "other": {"pairs": 8, "successes": 4, "against_successes": 7, "only": 0, "only_against": 3,
                  "sign_test_p": pytest.approx(0.25)}}
    assert pairs == pooled
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Paired episodes, tasks apart" in text
    assert "| ol | er | object | tasks 1 | 8 | 3 / 3 | 1 / 1 | 1 |" in text
    assert "| ol | er | object | the other tasks | 8 | 4 / 7 | 0 / 3 | 0.25 |" in text
    assert "tasks apart" not in (tmp_path / "pooled" / "report.md").read_text()
    assert predvla_main(["report", str(runs), "--out", str(tmp_path / "cli"), "--tasks-apart", "1"]) == 0
    assert json.loads((tmp_path / "cli" / "report.json").read_text())["tasks_apart"] == [1]
    for bad in ("1,x", "-1"):
        with pytest.raises(SystemExit):
            predvla_main(["report", str(runs), "--out", str(tmp_path / "bad"), "--tasks-apart", bad])
    assert "--tasks-apart expects integers and ranges such as 1-20 or 0,3,5; got '-1'" in capsys.readouterr().err


def test_the_per_task_ablation_figure_compares_the_same_episodes(tmp_path):
    """An ablation run on the first 2 of the intact model's 4 episodes per task: its per-task change is taken on
    those 2 pairs, not against the intact model's rate over all 4."""
    from lerobot_predvla.report import paired_task_rates

    runs = tmp_path / "runs"
    outcomes = {"er": {0: [True, False, True, True], 1: [False, False, True, True]},
                "a4": {0: [True, False], 1: [True, False]}}
    for config, tasks in outcomes.items():
        for task, successes in tasks.items():
            part = runs / "eval" / config / "libero_object" / "seed0" / f"task{task}"
            part.mkdir(parents=True)
            write_eval_info(part, {task: successes})
        atomic_write_json(runs / "records" / config / "libero_object" / "seed0.json", {
            "config": config, "suite": "libero_object", "seed": 0, "label": config,
            "group": "main" if config == "er" else "ablation", "compare_to": None if config == "er" else "er",
            "eval_overrides": None if config == "er" else {"er_lambda_v": 0.0}, "eval_seed": 0,
            "init_states": True, "n_episodes_per_task": len(tasks[0]), "episode_length": 600,
            "tasks": {str(t): {"successes": sum(s), "episodes": len(s)} for t, s in tasks.items()}})
    summary = write_report(runs, tmp_path / "report")
    # Task 0: er 1 of its first 2, a4 1: no change (the rates over all episodes would say 50 - 75 = -25).
    # Task 1: er 0 of its first 2, a4 1: +50 (the rates: 50 - 50 = 0).
    assert paired_task_rates(summary, "a4", "er", "libero_object") == {"0": (50.0, 0.0), "1": (0.0, 50.0)}
    assert paired_task_rates(summary, "a4", "other", "libero_object") is None
    assert summary["figures"]["pertask"] == FIGURES["pertask"] and (tmp_path / "report" / FIGURES["pertask"]).is_file()


def test_pooled_configurations_gather_their_seeds_and_paired_episodes(tmp_path):
    """`pool_with`: seed 0 at 4 episodes per task and seeds 1-2 at 2 in other configurations make one row over
    the three seeds (mean and sample std) and one paired comparison over all their episodes."""
    runs = tmp_path / "runs"
    outcomes = {  # (config, seed) -> per task, per episode
        ("er", 0): {0: [True, True, False, True], 1: [True, False, True, True]},
        ("ol", 0): {0: [True, False, False, False], 1: [False, False, True, True]},
        ("er_seeds", 1): {0: [True, False], 1: [False, False]},
        ("ol_seeds", 1): {0: [True, True], 1: [True, False]},
        ("er_seeds", 2): {0: [True, True], 1: [True, True]},
        ("ol_seeds", 2): {0: [False, True], 1: [True, True]},
    }
    describe = {"er": ("main", None, None), "ol": ("ablation", "er", None),
                "er_seeds": ("main", None, "er"), "ol_seeds": ("ablation", "er_seeds", "ol")}
    for (config, seed), tasks in outcomes.items():
        for task, successes in tasks.items():
            part = runs / "eval" / config / "libero_object" / f"seed{seed}" / f"task{task}"
            part.mkdir(parents=True)
            write_eval_info(part, {task: successes})
        group, compare_to, pool_with = describe[config]
        atomic_write_json(runs / "records" / config / "libero_object" / f"seed{seed}.json", {
            "config": config, "suite": "libero_object", "seed": seed, "group": group, "label": config,
            "compare_to": compare_to, "pool_with": pool_with, "eval_seed": seed, "init_states": True,
            "n_episodes_per_task": len(tasks[0]), "episode_length": 600,
            "tasks": {str(t): {"successes": sum(s), "episodes": len(s)} for t, s in tasks.items()}})
    summary = write_report(runs, tmp_path / "report")
    rates = {0: 75.0, 1: 25.0, 2: 100.0}  # er per seed: 6/8, 1/4, 4/4
    pooled = summary["pooled"]["er"]
    assert pooled["configs"] == ["er", "er_seeds"]
    cell = pooled["suites"]["libero_object"]
    assert cell["n"] == 3 and cell["seeds"] == {str(k): v for k, v in rates.items()}
    assert cell["mean"] == pytest.approx(np.mean(list(rates.values())))
    assert cell["std"] == pytest.approx(np.std(list(rates.values()), ddof=1))
    # Pairs: seed 0 only ol 0, only er 3 (as above); seed 1 only ol 2, only er 0; seed 2 only ol 0, only er 1.
    pairs = summary["pooled"]["ol"]["episodes"]["libero_object"]
    assert pairs == {"against": "er + er_seeds", "seeds": [0, 1, 2], "pairs": 16, "successes": 9,
                     "against_successes": 11, "only": 2, "only_against": 4,
                     "sign_test_p": pytest.approx(2 * (1 + 6 + 15) / 64)}
    text = (tmp_path / "report" / "report.md").read_text()
    main = text.split("## Main results")[1].split("\n## ")[0]
    assert f"| er, pooled seeds (er + er_seeds) | — | {cell['mean']:.2f} ± {cell['std']:.2f} |" in main
    ablations = text.split("## Ablations")[1].split("\n## ")[0]
    ol = summary["pooled"]["ol"]["suites"]["libero_object"]  # seeds 0-2: 3/8, 3/4, 3/4
    assert ol["mean"] == pytest.approx(np.mean([37.5, 75.0, 75.0]))
    assert f"|  | ol, pooled seeds (ol + ol_seeds) | {ol['mean']:.2f} ± {ol['std']:.2f} |" in ablations
    assert "| ol + ol_seeds | er + er_seeds | object | 0, 1, 2 | 16 | 9 / 11 | 2 / 4 | 0.688 |" in text
    # `--tasks-apart 1`: the pool's pairs of task 1 (seed 0: 2 / 3, only er 1; seed 1: 1 / 0, only ol 1; seed 2:
    # 2 / 2) and of task 0 (the rest), each summed over the pooled configurations.
    apart = write_report(runs, tmp_path / "apart", tasks_apart=[1])["pooled"]["ol"]["episodes"]["libero_object"]
    assert apart["apart"] == {
        "tasks": {"pairs": 8, "successes": 5, "against_successes": 5, "only": 1, "only_against": 1,
                  "sign_test_p": 1.0},
        "other": {"pairs": 8, "successes": 4, "against_successes": 6, "only": 1, "only_against": 3,
                  "sign_test_p": pytest.approx(0.625)}}
    assert "| ol + ol_seeds | er + er_seeds | object | tasks 1 | 8 | 5 / 5 | 1 / 1 | 1 |" in (
        tmp_path / "apart" / "report.md").read_text()


def test_a_seed_in_two_pooled_configurations_is_an_error(tmp_path):
    from lerobot_predvla.report import ReportError

    runs = tmp_path / "runs"
    for config, pool_with in (("er", None), ("er_seeds", "er")):
        atomic_write_json(runs / "records" / config / "libero_object" / "seed0.json", {
            "config": config, "suite": "libero_object", "seed": 0, "group": "main", "pool_with": pool_with,
            "tasks": {"0": {"successes": 1, "episodes": 2}}})
    with pytest.raises(ReportError, match=r"seeds \[0\] of libero_object"):
        write_report(runs, tmp_path / "report")


def test_runs_share_their_starts_only_with_the_same_seed_and_resets():
    from lerobot_predvla.report import same_starts

    official = {"eval_seed": 0, "init_states": True, "episode_length": 280, "n_episodes_per_task": 10}
    assert same_starts(official, {**official, "n_episodes_per_task": 20})  # episode i: official init state i
    assert not same_starts(official, {**official, "eval_seed": 1})
    assert not same_starts(official, {**official, "episode_length": 600})
    resets = {**official, "init_states": False, "eval_seed": 1000, "n_episodes_per_task": 5}
    assert same_starts(resets, dict(resets)) and not same_starts(resets, official)
    assert not same_starts(resets, {**resets, "n_episodes_per_task": 10})


def test_paper_section_sets_the_published_numbers_beside_ours(runs, tmp_path):
    """A configuration's `paper` (mean and std, or the mean alone) becomes a row beside our mean over seeds."""
    write_report(runs, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "## Beside the paper" in text
    for name, label, paper, shown in (("predvla", "PredVLA", 89.24, "89.24 ± 6.13"),
                                      ("A6", "- Online ER", 78.14, "78.14")):
        ours = [rate(name, "libero_object", s) for s in SEEDS]
        mean, std = float(np.mean(ours)), float(np.std(ours, ddof=1))
        assert f"| {label} | object | {mean:.2f} ± {std:.2f} | {shown} | {mean - paper:+.2f} |" in text
    section = text.split("## Beside the paper")[1].split("\n## ")[0]
    assert section.count("| object |") == 2  # only the configurations with a published number


def test_starts_and_mechanism_sections_read_the_files_beside_the_report(runs, tmp_path):
    """start_spread.json and inspect/seed<N>/inspect.json beside the report become two sections with their numbers."""
    out = tmp_path / "report"
    out.mkdir()
    spread = {"tasks": {str(t): {kind: {"starts": 50, "joint_std": j, "object_std": {"a": s, "b": 2 * s},
                                        "object_mean": {"a": [0.1, 0.2], "b": [0.3, 0.4 + d]}}
                                 for kind, j, s, d in (("demonstrations", 0.02, 0.002, 0.003),
                                                       ("official", 0.01, 0.001, 0.0))}
                        for t in range(2)}}
    (out / "start_spread.json").write_text(json.dumps(spread))
    step = {"language": {"open_loop_picks_own_task": 0.3, "mean_language_swap_mse": 0.0271, "mean_demo_gap": 0.1033},
            "proprio_error_per_dim": {"removed": {"proprio": 0.29, "vision": 0.087}},
            "posteriors": {m: {"prior_gap": g} for m, g in zip(("T", "V", "A_top", "A_bottom"), (0.1, 0.2, 0.3, 0.4),
                                                              strict=True)}}
    (out / "inspect" / "seed0").mkdir(parents=True)
    (out / "inspect" / "seed0" / "inspect.json").write_text(json.dumps(
        {"history": [{"step": 5000, **step}, {"step": 10000, **step, "proprio_error_per_dim": {
            "removed": {"proprio": 0.29, "vision": 0.087, "action": 0.9999}}}]}))
    (out / "inspect" / "seed0_030000").mkdir()  # one checkpoint inspected on its own: cited elsewhere, not a seed
    (out / "inspect" / "seed0_030000" / "inspect.json").write_text(json.dumps({"history": [{"step": None, **step}]}))
    write_report(runs, out)
    text = (out / "report.md").read_text()
    assert "### seed0_030000" not in text
    assert "## Demonstrations' starts" in text and "within 3.0 mm" in text
    assert "| arm joints, std over starts (rad) | 0.0200 | 0.0100 |" in text
    assert "| objects, std of x, y over starts (mm) | 3.00 | 1.50 |" in text
    assert "## The mechanism over training" in text and "### seed0" in text
    # A history written before the action error was reported shows it as missing.
    assert f"| 5,000 | 30 | 0.027 / 0.103 | 29 / 9 / {MISSING} | 0.100 / 0.200 / 0.300 / 0.400 |" in text
    assert "| 10,000 | 30 | 0.027 / 0.103 | 29 / 9 / 100 | 0.100 / 0.200 / 0.300 / 0.400 |" in text


def test_baselines_learning_rates_from_the_sweeps_selection(runs, tmp_path):
    """RUNS_DIR/lr_sweep/<config>/<suite>.json becomes a table: each rate's held-out NLL, the chosen one."""
    import shutil

    runs_copy = tmp_path / "runs"
    shutil.copytree(runs, runs_copy)
    selection = {"config": "B2", "suite": "libero_object",
                 "heldout_nll": {"0.0001": -3.25, "0.001": -4.5, "0.003": None}, "chosen_lr": 0.001,
                 "steps": 10000, "heldout_episodes": {"0": [45, 46], "1": [95]}}
    (runs_copy / "lr_sweep" / "B2").mkdir(parents=True)
    (runs_copy / "lr_sweep" / "B2" / "libero_object.json").write_text(json.dumps(selection))
    write_report(runs_copy, tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## Baselines' learning rates" in text
    assert "| B2 | object | -3.250 | -4.500 | — | 0.001 | 10,000 | 3 |" in text


def test_baselines_learning_rates_of_a_sweep_still_running(runs, tmp_path):
    """Before the selection exists, the finished candidates (RUNS_DIR/lr_sweep/<config>/<suite>/lr<rate>.json) show
    as a pending row; the selection, once written, replaces them."""
    import shutil

    runs_copy = tmp_path / "runs"
    shutil.copytree(runs, runs_copy)
    folder = runs_copy / "lr_sweep" / "B1" / "libero_object"
    folder.mkdir(parents=True)
    for rate, loss in ((0.0001, -13.39), (0.0003, -13.64)):
        (folder / f"lr{rate:g}.json").write_text(json.dumps({"lr": rate, "heldout_nll": loss, "steps": 10000}))
    write_report(runs_copy, tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    assert f"| B1 | object | -13.390 | -13.640 | pending (2 candidates done) | 10,000 | {MISSING} |" in text
    selection = {"config": "B1", "suite": "libero_object", "heldout_nll": {"0.0001": -13.39, "0.0003": -13.64},
                 "chosen_lr": 0.0003, "steps": 10000, "heldout_episodes": {"0": [45, 46]}}
    (folder.parent / "libero_object.json").write_text(json.dumps(selection))
    write_report(runs_copy, tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    assert "| B1 | object | -13.390 | -13.640 | 0.0003 | 10,000 | 2 |" in text and "pending" not in text


def test_fresh_clone_section_names_what_is_read_and_what_is_redone(tmp_path, monkeypatch):
    """A training whose record names a model outside the runs dir's train/ is read from there; one whose checkpoint
    lies in train/ is redone, unless it is a learning-rate candidate whose held-out result is committed; data stages
    are recomputed, with their recorded time."""
    from lerobot_predvla.report import fresh_clone_section
    from lerobot_predvla.sweep import TRAIN_DONE_FILE

    monkeypatch.chdir(tmp_path)
    runs = tmp_path / "results" / "x" / "runs"
    atomic_write_json(runs / "data" / "libero_object.json", {"demos": {"command": [], "wall_s": 600},
                                                             "convert": {"command": [], "wall_s": 300}})
    for seed, checkpoint in ((0, "../../../checkpoints/x/predvla_seed0"),
                             (1, "train/predvla/libero_object/seed1/checkpoints/030000/pretrained_model")):
        atomic_write_json(runs / "train" / "predvla" / "libero_object" / f"seed{seed}" / TRAIN_DONE_FILE,
                          {"checkpoint": checkpoint, "steps": 30000})
    # A learning-rate candidate: its checkpoint is local, but its committed held-out result is all the sweep reads.
    atomic_write_json(runs / "train" / "B1_lr0.0003" / "libero_object" / "seed0" / TRAIN_DONE_FILE,
                      {"checkpoint": "train/B1_lr0.0003/libero_object/seed0/checkpoints/010000/pretrained_model",
                       "steps": 10000})
    atomic_write_json(runs / "lr_sweep" / "B1" / "libero_object" / "lr0.0003.json", {"lr": 0.0003})
    atomic_write_json(runs / "train" / "B1_lr0.001" / "libero_object" / "seed0" / TRAIN_DONE_FILE,
                      {"checkpoint": "train/B1_lr0.001/libero_object/seed0/checkpoints/010000/pretrained_model",
                       "steps": 10000})
    text = "\n".join(fresh_clone_section(runs))
    assert ("| training B1_lr0.0003 / libero_object / seed 0 | not needed: its held-out result is read from "
            "`results/x/runs/lr_sweep/B1/libero_object/lr0.0003.json` |") in text
    assert "| training B1_lr0.001 / libero_object / seed 0 | redone (10,000 steps)" in text
    assert "| data of libero_object (demos, convert) | recomputed from the sweep file (15 min as recorded)" in text
    assert "| training predvla / libero_object / seed 0 | read from `checkpoints/x/predvla_seed0` |" in text
    assert "| training predvla / libero_object / seed 1 | redone (30,000 steps)" in text
    assert fresh_clone_section(tmp_path / "empty") == []


def test_training_time_counts_every_call_in_the_training_log(tmp_path):
    """A resumed training's record times its last lerobot-train call; the stage table sums the calls in its log,
    for the run that trained and for one evaluating its checkpoint; without a log, the record's time stands."""
    from lerobot_predvla.report import stages_section

    log = tmp_path / "logs" / "predvla" / "libero_object" / "seed0.train.log"
    log.parent.mkdir(parents=True)
    log.write_text("$ torchrun lerobot-train --steps=30\nINFO 2026-11-26 12:00:00 ot_train.py:441 cfg.steps=30\n"
                   "INFO 2026-11-26 13:00:00 ot_train.py:641 step:10\n"
                   "$ torchrun lerobot-train --resume=true\nINFO 2026-11-26 14:00:00 ot_train.py:441 cfg.steps=30\n"
                   "INFO 2026-11-26 14:30:00 ot_train.py:641 step:30\n")
    tasks = {"0": {"successes": 1, "episodes": 2}}
    records = [{"config": "predvla", "suite": "libero_object", "seed": 0, "steps": 30, "train_wall_s": 1800.0,
                "tasks": tasks},
               {"config": "A6", "checkpoint_from": "predvla", "suite": "libero_object", "seed": 0, "steps": 30,
                "train_wall_s": 1800.0, "tasks": tasks},
               {"config": "predvla", "suite": "libero_object", "seed": 1, "steps": 30, "train_wall_s": 600.0,
                "tasks": tasks}]
    table = "\n".join(stages_section(records, tmp_path)).splitlines()
    rows = [line for line in table if line.startswith("| ") and "libero_object" in line]
    assert [line.split(" | ")[4] for line in rows] == ["90 (2 calls)", "90 (2 calls)", "10"]


def test_a_committed_report_regenerates_identically(tmp_path, monkeypatch):
    """`predvla report` on the committed runs of results/libero_object_table2 writes its committed report.json and
    report.md, whichever checkout regenerates them (recorded commands lose the recording machine's path heads); the
    demonstrations' starts and the inspections beside the report are read where they are."""
    repo = Path(__file__).resolve().parents[1]
    committed = repo / "results" / "libero_object_table2"
    monkeypatch.chdir(repo)  # the report names RUNS_DIR as given, and paths relative to the repository root
    for name in (START_SPREAD_FILE, INSPECT_DIR):
        (tmp_path / name).symlink_to(committed / name)
    write_report(Path("results/libero_object_table2/runs"), tmp_path)
    assert (tmp_path / "report.json").read_text() == (committed / "report.json").read_text()
    assert (tmp_path / "report.md").read_text() == (committed / "report.md").read_text()


def test_recorded_commands_lose_the_recording_checkouts_path_heads():
    command = ["/elsewhere/repo/.venv/bin/lerobot-train", "--dataset.root=/elsewhere/repo/outputs/x/dataset",
               "/other/clone/results/x/runs", "--policy.path=checkpoints/p", "--env.task_ids=[0]", "--x=/etc/y"]
    assert _relative(command) == ("lerobot-train --dataset.root=outputs/x/dataset results/x/runs "
                                  "--policy.path=checkpoints/p '--env.task_ids=[0]' --x=/etc/y")
