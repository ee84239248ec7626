"""`pool_sets`: one paired comparison pooled over evaluation sets (docs/research/demonstrations.md: "pooled over E1-E3
(90 pairs)"), checked when the sweep file is loaded, counted by `predvla report` (synthetic records), and set in the
demonstrations screens' sweep files."""

from pathlib import Path

import pytest
from sweep_factory import sweep_file

from lerobot_predvla.report import sign_test, write_report
from lerobot_predvla.sweep import Sweep, SweepError
from lerobot_predvla.utils.io import atomic_write_json

OPEN_LOOP = {"er_iterations": 0}
SHIFTED = ["--env.object_shift_cm=4", "--env.object_shift_pattern=cross"]
SETS = {"": {}, "_resets": {"init_states": False, "eval_seed": 3000}, "_shifted": {"eval_args": SHIFTED}}


def configs(**changes) -> list[dict]:
    """Error regression and exact open loop of one model on the three sets; `changes` per configuration name."""
    entries = [{"name": "er", "group": "main"}]
    for suffix, evaluation in SETS.items():
        if suffix:
            entries.append({"name": f"er{suffix}", "group": "ablation", "checkpoint_from": "er", **evaluation})
        entries.append({"name": f"ol{suffix}", "group": "ablation", "checkpoint_from": "er",
                        "compare_to": f"er{suffix}", "eval_overrides": OPEN_LOOP, **evaluation})
    entries[1]["pool_sets"] = ["ol_resets", "ol_shifted"]
    return [{**e, **changes.get(e["name"], {})} for e in entries]


def test_a_pool_lists_the_same_comparison_on_other_evaluation_sets(tmp_path):
    assert Sweep.load(sweep_file(tmp_path, configs=configs())).configs["ol"].pool_sets == ["ol_resets", "ol_shifted"]


@pytest.mark.parametrize("changes, message", [
    ({"ol": {"pool_sets": "ol_resets"}}, "expected a non-empty list"),
    ({"ol": {"pool_sets": ["ol_resets", "nope"]}}, "refers to unknown configuration 'nope'"),
    ({"ol_resets": {"eval_overrides": {}}}, "ol_resets must make the comparison ol makes"),
    ({"er_resets": {"eval_overrides": OPEN_LOOP}}, "with a compare_to evaluated as 'er' is"),
    ({"ol_resets": {"compare_to": None}}, "ol_resets must make the comparison"),
    ({"ol_shifted": {"eval_args": []}, "er_shifted": {"eval_args": []}}, "two of its configurations evaluate on the "
                                                                          "same set"),
    ({"ol_resets": {"pool_sets": ["ol_shifted"]}}, "list other configurations, which list none themselves"),
])
def test_a_pool_of_other_comparisons_or_of_one_set_twice_is_refused(tmp_path, changes, message):
    with pytest.raises(SweepError, match=f"configuration ol(: pool_sets .*| ){message}"):
        Sweep.load(sweep_file(tmp_path, configs=configs(**changes)))


def test_a_pooled_configurations_unknown_compare_to_is_named_not_a_key_error(tmp_path):
    """The pool's check follows each listed configuration's compare_to, so references are checked before it."""
    with pytest.raises(SweepError, match="configuration ol_shifted refers to unknown configuration 'nope'"):
        Sweep.load(sweep_file(tmp_path, configs=configs(ol_shifted={"compare_to": "nope"})))


def test_a_configuration_in_two_pools_is_refused(tmp_path):
    entries = configs()
    entries.append({**entries[-1], "name": "ol_shifted_again", "compare_to": "er_shifted", "pool_sets": ["ol_shifted"],
                    "eval_args": [*SHIFTED, "--env.render_interval=100000"]})
    with pytest.raises(SweepError, match=r"configurations \['ol_shifted'\] are listed in more than one `pool_sets`"):
        Sweep.load(sweep_file(tmp_path, configs=entries))


def test_the_report_pools_the_paired_episodes_of_the_sets_into_one_sign_test(tmp_path):
    """Three sets of 4 pairs (seed 0 each): one row per set in "Paired episodes", then their 12 pairs pooled."""
    runs = tmp_path / "runs"
    outcomes = {  # config -> task 0's episodes
        "er": [True, True, False, True], "ol": [True, False, False, False],
        "er_resets": [True, True, True, False], "ol_resets": [False, True, False, True],
        "er_shifted": [True, False, False, False], "ol_shifted": [False, False, False, False],
    }
    described = {e["name"]: e for e in configs()}
    for config, successes in outcomes.items():
        spec = described[config]
        part = runs / "eval" / config / "libero_object" / "seed0"
        atomic_write_json(part / "eval_info.json", {"per_task": [
            {"task_group": "libero_object", "task_id": 0, "metrics": {"successes": successes}}]})
        atomic_write_json(runs / "records" / config / "libero_object" / "seed0.json", {
            "config": config, "suite": "libero_object", "seed": 0, "group": spec["group"], "label": config,
            "compare_to": spec.get("compare_to"), "pool_sets": spec.get("pool_sets"),
            "eval_seed": spec.get("eval_seed", 0), "init_states": spec.get("init_states", True),
            "n_episodes_per_task": 4, "episode_length": 600,
            "tasks": {"0": {"successes": sum(successes), "episodes": 4}}})
    summary = write_report(runs, tmp_path / "report")
    # Only open loop / only error regression: official 0 / 2, resets 1 / 2, shifted 0 / 1.
    pooled = summary["pooled_sets"]["ol"]
    assert pooled["configs"] == ["ol", "ol_resets", "ol_shifted"]
    assert pooled["episodes"]["libero_object"] == {
        "against": "er + er_resets + er_shifted", "seeds": [0], "pairs": 12, "successes": 3, "against_successes": 7,
        "only": 1, "only_against": 5, "sign_test_p": sign_test(1, 5)}
    text = (tmp_path / "report" / "report.md").read_text()
    assert (f"| ol + ol_resets + ol_shifted, pooled over evaluation sets | er + er_resets + er_shifted | object | 0 | "
            f"12 | 3 / 7 | 1 / 5 | {sign_test(1, 5):.3g} |") in text
    assert "| ol_resets | er_resets | object | 0 | 4 | 2 / 3 | 1 / 2 |" in text
    (runs / "records" / "ol_shifted" / "libero_object" / "seed0.json").unlink()  # not run yet, and no plan
    pooled = write_report(runs, tmp_path / "report")["pooled_sets"]["ol"]
    assert pooled["configs"] == ["ol", "ol_resets"] and pooled["episodes"]["libero_object"]["pairs"] == 8


def test_the_demonstrations_screens_pool_each_comparison_over_e1_to_e3():
    """Within each PredVLA (error regression, carried) and each BC against exact open loop: official states, resets
    and shifted objects, 3 tasks x 10 episodes each, 90 pairs; the same pools in the three screens."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    for name in ("scripted", "teleop", "teleop_placed"):
        sweep = Sweep.load(sweeps / f"libero_object_demos_{name}.yaml")
        pools = {n: c.pool_sets for n, c in sweep.configs.items() if c.pool_sets}
        targets = ("olt_open_loop", "olt_carried", "table2_open_loop", "table2_carried", "B1", "B2")
        assert pools == {t: [f"{t}_resets", f"{t}_shifted"] for t in targets}, name
        episodes = len(sweep.settings.eval_tasks) * sweep.settings.n_episodes
        assert all(episodes * len([t, *members]) == 90 for t, members in pools.items())
