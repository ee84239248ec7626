"""The committed sweep files: valid, reading every policy file, and the protocols they state (corruption points,
randomised resets, the reading screen, the init-noise demonstrations)."""

import json
from pathlib import Path

import pytest
from sweep_factory import FakeLeRobot, arg, differing_flags, sweep_file

from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.sweep import (
    Run,
    Runner,
    Sweep,
    SweepError,
)


def test_the_paper_sweep_file_is_valid():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    assert sweep.settings.n_episodes == 50 and sweep.settings.episode_length == 600 and len(sweep.settings.seeds) == 14
    assert sweep.configs["A6"].checkpoint_from == "predvla" and sweep.configs["L2b"].branch
    assert len(sweep.runs(["predvla"])) == 56 and len(sweep.runs(["A1"])) == 21


def test_the_libero_demo_sweep_file_is_valid():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_demo.yaml")
    assert sweep.settings.train_device == "cpu" and sweep.settings.eval_args == ["--env.task_ids=[0]"]
    assert len(sweep.runs()) == 6 and sweep.configs["A4"].compare_to == "predvla"
    assert sweep.settings.datasets["libero_object"]["root"].endswith("outputs/libero_demo/dataset")


def test_randomised_resets_evaluate_from_their_own_seed_and_are_recorded(tmp_path):
    configs = [{"name": "predvla", "group": "main"},
               {"name": "fresh", "group": "ablation", "checkpoint_from": "predvla", "init_states": False,
                "eval_seed": 1000}]
    fake = FakeLeRobot()
    runner = Runner(Sweep.load(sweep_file(tmp_path, configs=configs, seeds=[0], suites=["libero_object"])),
                    tmp_path / "runs", execute=fake)
    assert not runner.run(progress=False)["failed"]
    evals = {arg(c, "output_dir").split("/eval/")[1].split("/")[0]: c for c in fake.commands
             if c[0].endswith("lerobot-eval")}
    assert arg(evals["predvla"], "env.init_states") == "true" and arg(evals["predvla"], "seed") == "0"
    assert arg(evals["fresh"], "env.init_states") == "false" and arg(evals["fresh"], "seed") == "1000"
    assert fake.count("lerobot-train") == 1  # the resets reuse the trained checkpoint
    record = json.loads((tmp_path / "runs/records/fresh/libero_object/seed0.json").read_text())
    assert record["init_states"] is False and record["eval_seed"] == 1000
    base = json.loads((tmp_path / "runs/records/predvla/libero_object/seed0.json").read_text())
    assert base["init_states"] is True and base["eval_seed"] == 0


def test_the_libero_object_cpu_sweep_file_is_valid(tmp_path):
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_object_cpu.yaml")
    assert sweep.settings.eval_tasks == list(range(10))
    assert sweep.settings.data["libero_object"].language_from == "libero"
    runner = Runner(sweep, tmp_path)
    train = runner.train_command(sweep.configs["predvla_cpu"], "libero_object", 0)
    assert "--policy.open_loop_weight=1.0" in train and "--policy.optimizer_lr=0.001" in train
    assert "--steps=4000" in train and not any(a.startswith("--policy.complexity_weights") for a in train)
    # The shipped checkpoints/predvla_libero_object: the recipe trained 8,000 steps.
    shipped = runner.train_command(sweep.configs["predvla_cpu_8k"], "libero_object", 0)
    assert "--steps=8000" in shipped and "--policy.open_loop_weight=1.0" in shipped
    assert sweep.configs["predvla_cpu_8k_open_loop"].checkpoint_from == "predvla_cpu_8k"
    ablation = runner.train_command(sweep.configs["predvla_cpu_no_open_loop_term"], "libero_object", 0)
    assert "--policy.open_loop_weight=0.0" in ablation
    assert "--policy.type=predvla_bc_rnn" in runner.train_command(sweep.configs["B2"], "libero_object", 0)
    fresh = sweep.configs["predvla_cpu_8k_random_resets"]
    assert fresh.checkpoint_from == "predvla_cpu_8k" and not fresh.init_states and fresh.eval_seed == 1000


def test_the_reading_screen_changes_one_reading_per_configuration(tmp_path):
    """configs/sweeps/libero_object_reading.yaml (docs/research/dynamics.md): each training reading reaches
    lerobot-train as the config field it names, a dict-typed field whole as JSON (draccus parses no other form)."""
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_object_reading.yaml")
    runner = Runner(sweep, tmp_path)
    train = {name: runner.train_command(sweep.configs[name], "libero_object", 0)
             for name in ("table2", "mean", "scaled", "dense", "open_loop_term")}
    assert all("--steps=10000" in c and "--batch_size=32" in c for c in train.values())
    assert "--policy.complexity_reduction=mean" in train["mean"]
    assert "--policy.posterior_adam=dense" in train["dense"]
    assert "--policy.open_loop_weight=1.0" in train["open_loop_term"]
    mapping = [a for a in train["scaled"] if a.startswith("--policy.normalization_mapping=")]
    assert len(mapping) == 1 and json.loads(mapping[0].split("=", 1)[1])["STATE"] == "MEAN_STD"
    readings = {"--policy.type=predvla", "--policy.push_to_hub=false", "--policy.device=cpu"}
    assert {a for a in train["table2"] if a.startswith("--policy.")} == readings  # the defaults: Table 2
    assert sweep.configs["scaled_gd"].eval_overrides == {"er_optimizer": "gd"}
    assert sweep.settings.eval_tasks == [1, 4, 7] and sweep.settings.n_episodes == 10


@pytest.mark.parametrize(("sweep_name", "readings"), [
    ("libero_object_lr_screen.yaml",
     {"network_lr": {"optimizer_lr": "0.001"}, "posterior_lr": {"posterior_lr": "0.001"}}),
    ("libero_object_fit_sensory.yaml",
     {"fit_sensory": {"posteriors_fit_actions": "false"},
      "fit_sensory_olt": {"posteriors_fit_actions": "false", "open_loop_weight": "1.0"}}),
])
def test_a_later_screen_changes_only_its_fields_and_keeps_the_first_screens_protocol(tmp_path, sweep_name, readings):
    """A later screen (the learning rates; the posteriors fitted without the action term): each reading is Table 2
    with only its fields changed, trained and evaluated exactly as the first screen's `table2` (its reference on the
    same episodes)."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    first, later = (Sweep.load(sweeps / f) for f in ("libero_object_reading.yaml", sweep_name))
    assert later.settings == first.settings  # `extends`
    reference = Runner(first, tmp_path / "first").train_command(first.configs["table2"], "libero_object", 0)
    runner = Runner(later, tmp_path / "later")
    for name, fields in readings.items():
        train = runner.train_command(later.configs[name], "libero_object", 0)
        assert all(f"--policy.{field}={value}" in train for field, value in fields.items()), train
        differ = differing_flags(train, reference)
        assert differ <= {*(f"--policy.{f}" for f in fields), "--output_dir", "--job_name"}, differ
        assert later.configs[f"{name}_open_loop"].eval_args == first.configs["table2_open_loop"].eval_args
        assert later.configs[f"{name}_open_loop"].eval_overrides == first.configs["table2_open_loop"].eval_overrides
        if f"{name}_gd" in later.configs:
            assert later.configs[f"{name}_gd"].eval_overrides == first.configs["table2_gd"].eval_overrides


def test_the_follow_up_evaluates_the_screens_open_loop_term_model_with_one_inference_setting_changed(tmp_path):
    """configs/sweeps/libero_object_olt_er.yaml: the screen's open_loop_term training and open loop unchanged (so the
    linked runs are found, not repeated), and each error-regression setting one field away from Table 2's."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    screen, follow_up = (Sweep.load(sweeps / f) for f in ("libero_object_reading.yaml", "libero_object_olt_er.yaml"))
    assert follow_up.settings == screen.settings
    for name in ("open_loop_term", "open_loop_term_open_loop"):
        assert follow_up.configs[name] == screen.configs[name], name
    changed = {"olt_carried": {"er_adam_state": "carried"}, "olt_eta_0005": {"er_lr": 0.005},
               "olt_w_er_10": {"er_complexity_weight": 10.0}, "olt_proprio_only": {"er_lambda_v": 0.0}}
    assert set(follow_up.configs) == {"open_loop_term", "open_loop_term_open_loop", *changed}
    assert_one_inference_setting_away(follow_up, "open_loop_term", changed, tmp_path)


def assert_one_inference_setting_away(follow_up: Sweep, model: str, changed: dict[str, dict], tmp_path: Path) -> None:
    """Each configuration of `changed` evaluates `model`'s checkpoint with its one error-regression override, paired
    with `model`'s exact open loop, and its lerobot-eval command differs from `model`'s in that flag alone."""
    runner = Runner(follow_up, tmp_path)
    reference = runner.eval_command(Run(model, "libero_object", 0), tmp_path / "ckpt")
    for name, overrides in changed.items():
        spec = follow_up.configs[name]
        assert spec.checkpoint_from == model and spec.compare_to == f"{model}_open_loop"
        assert spec.eval_overrides == overrides
        command = runner.eval_command(Run(name, "libero_object", 0), tmp_path / "ckpt")
        differ = differing_flags(command, reference)
        assert differ <= {f"--policy.{next(iter(overrides))}", "--output_dir"}, differ


@pytest.mark.parametrize(("sweep_name", "parent", "model"), [
    ("libero_object_fit_sensory_er.yaml", "libero_object_fit_sensory.yaml", "fit_sensory_olt"),
    ("libero_object_reading_oracle_er.yaml", "libero_object_reading_oracle.yaml", "oracle_fit_sensory"),
])
def test_the_update_follow_up_evaluates_a_trained_model_with_one_inference_setting_changed(tmp_path, sweep_name,
                                                                                            parent, model):
    """The error-regression update on the fit_sensory models: the parent run's settings and training unchanged (so the
    linked training is found, not repeated), the exact open loop as the parent's (rendering only at reset, which
    changes no action), and each update one field away from Table 2's error regression."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    base, follow_up = Sweep.load(sweeps / parent), Sweep.load(sweeps / sweep_name)
    assert follow_up.settings == base.settings
    assert follow_up.configs[model] == base.configs[model]
    open_loop = follow_up.configs[f"{model}_open_loop"]
    assert (open_loop.checkpoint_from, open_loop.eval_overrides) == (model, {"er_iterations": 0})
    assert open_loop.eval_args == ["--env.render_interval=100000"]
    changed = {f"{model}_carried": {"er_adam_state": "carried"}, f"{model}_gd": {"er_optimizer": "gd"}}
    assert set(follow_up.configs) == {model, f"{model}_open_loop", *changed}
    assert_one_inference_setting_away(follow_up, model, changed, tmp_path)


def test_the_confirmation_and_the_oracle_evaluate_the_screens_readings_on_the_same_episodes(tmp_path, capsys):
    """The confirmation is the screen's own sweep file with `--n-episodes 50 --eval-tasks 1,3,4,7` (its configurations
    and checkpoints, more episodes); libero_object_reading_oracle.yaml trains the same readings on the oracle's
    features (the later fit_sensory screen's too), converted by the data stage with --oracle, and evaluates them with
    the env's oracle on the confirmation's episodes."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    screen = Sweep.load(sweeps / "libero_object_reading.yaml")
    oracle = Sweep.load(sweeps / "libero_object_reading_oracle.yaml")
    assert predvla_main(["sweep", str(sweeps / "libero_object_reading.yaml"), "--runs-dir", str(tmp_path / "confirm"),
                         "--configs", "table2,table2_open_loop", "--n-episodes", "50", "--eval-tasks", "1,3,4,7",
                         "--dry-run"]) == 0
    evaluations = [line for line in capsys.readouterr().out.splitlines() if "lerobot-eval" in line]
    assert len(evaluations) == 8  # two modes x four tasks, one lerobot-eval each
    assert all("--eval.n_episodes=50" in line and "--env.init_states=true" in line for line in evaluations)
    assert sorted(line.rsplit("task_ids=[", 1)[1][0] for line in evaluations) == sorted("13471347")
    assert oracle.settings.eval_tasks == [1, 3, 4, 7] and oracle.settings.n_episodes == 50
    assert oracle.settings.steps == screen.settings.steps and oracle.settings.seeds == screen.settings.seeds
    screen_runner, oracle_runner = Runner(screen, tmp_path / "screen"), Runner(oracle, tmp_path / "oracle")
    later = Sweep.load(sweeps / "libero_object_fit_sensory.yaml")  # the later screen's readings have twins too
    for name, spec in {**screen.configs, **later.configs}.items():
        twin = oracle.configs[f"oracle_{name}"]
        assert twin.eval_overrides == spec.eval_overrides and twin.checkpoint_from == (
            spec.checkpoint_from and f"oracle_{spec.checkpoint_from}")
        if spec.checkpoint_from is None:  # the same training command but for the dataset
            ours = oracle_runner.train_command(twin, "libero_object", 0)
            theirs = screen_runner.train_command(spec, "libero_object", 0)
            differ = differing_flags(ours, theirs)
            assert differ <= {"--dataset.repo_id", "--dataset.root", "--output_dir", "--job_name",
                              "--policy.vision_dim_per_camera"}, differ
    evaluation = oracle_runner.eval_command(Run("oracle_mean_gd", "libero_object", 0), tmp_path / "ckpt")
    assert "--env.oracle=true" in evaluation and "--policy.er_optimizer=gd" in evaluation
    spec = oracle.settings.data["libero_object"]
    spec.hdf5, spec.frontend = str(tmp_path / "hdf5"), str(tmp_path / "frontend")
    oracle.settings.datasets["libero_object"]["root"] = str(tmp_path / "dataset")
    stages = dict(Runner(oracle, tmp_path).data_commands("libero_object"))
    assert "--oracle" in stages["convert"] and "--oracle" not in stages["frontend"]


def test_the_init_noise_sweep_records_demonstrations_that_start_like_the_official_init_states(tmp_path):
    """The arm's initial joint noise, the half-turn rule and the holds after success reach `predvla demos`;
    libero_object_cpu.yaml keeps the fixed start."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    for name, noise, half_turn, hold in (("libero_object_cpu_init_noise.yaml", "0.02", "nearest", "0"),
                                         ("libero_object_cpu_init_noise_wrist.yaml", "0.02", "wrist_centre", "0"),
                                         ("libero_object_cpu_hold.yaml", "0.02", "wrist_centre", "40"),
                                         ("libero_object_cpu.yaml", "0.0", "nearest", "0")):
        sweep = Sweep.load(sweeps / name)
        spec = sweep.settings.data["libero_object"]  # outputs in tmp_path: nothing made on this machine counts
        spec.hdf5, spec.frontend = str(tmp_path / name / "hdf5"), str(tmp_path / name / "frontend")
        sweep.settings.datasets["libero_object"]["root"] = str(tmp_path / name / "dataset")
        stage, command = Runner(sweep, tmp_path).data_commands("libero_object")[0]
        assert stage == "demos" and command[command.index("--init-noise") + 1] == noise
        assert command[command.index("--half-turn") + 1] == half_turn
        assert command[command.index("--hold-steps") + 1] == hold


def test_paper_sweep_reads_every_policy_file():
    """configs/policy/*.json are `lerobot-train --config_path` files; the sweep takes their nested policy."""
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    base = Path(__file__).parents[1] / "configs" / "sweeps"
    types = {name: spec.policy_args(base, "libero_object")[0] for name, spec in sweep.configs.items()}
    assert types["B1"] == "--policy.type=predvla_bc_transformer" and types["B2"] == "--policy.type=predvla_bc_rnn"
    assert types["L3"] == "--policy.type=predvla_ladder"
    assert "--policy.chunk_size=8" in sweep.configs["B3"].policy_args(base, "libero_object")


def test_corruption_points_evaluate_with_an_unrelated_episode_of_another_suite(tmp_path):
    corruption = {"name": "Cp25", "group": "corruption", "checkpoint_from": "predvla", "compare_to": "predvla",
                  "corruption": {"channel": "proprio", "alpha": 0.25, "open_loop": "A6", "episode": 3},
                  "suites": ["libero_object"]}
    path = sweep_file(tmp_path, configs=[{"name": "predvla"}, corruption])
    runner = Runner(Sweep.load(path), tmp_path / "runs", execute=FakeLeRobot())
    command = runner.eval_command(Run("Cp25", "libero_object", 0), tmp_path / "ckpt")
    assert arg(command, "policy.er_corruption_channel") == "proprio"
    assert arg(command, "policy.er_corruption_alpha") == "0.25"
    assert arg(command, "policy.er_corruption_episode") == "3"
    # libero_object is corrupted from libero_spatial's dataset, libero_spatial from libero_goal's (missing here).
    assert arg(command, "policy.er_corruption_root") == str((tmp_path / "data" / "libero_spatial").resolve())
    assert arg(runner.eval_command(Run("predvla", "libero_object", 0), tmp_path / "ckpt"),
               "policy.er_corruption_channel") is None
    with pytest.raises(SweepError, match="corruption source suites \\['libero_goal'\\]"):
        Sweep.load(sweep_file(tmp_path, configs=[{"name": "predvla"}, {**corruption, "suites": ["libero_spatial"]}]))
    with pytest.raises(SweepError, match="channel"):
        Sweep.load(sweep_file(tmp_path, configs=[{"name": "predvla"}, {**corruption, "corruption": {"alpha": 1}}]))
    hub_only = {s: {"repo_id": f"local/{s}"} for s in ("libero_object", "libero_spatial")}
    with pytest.raises(SweepError, match=r"corruption source datasets of \['libero_spatial'\] need a local `root`"):
        Sweep.load(sweep_file(tmp_path, datasets=hub_only, configs=[{"name": "predvla"}, corruption]))
    runner.run(progress=False)
    record = json.loads(runner.record_path(Run("Cp25", "libero_object", 0)).read_text())
    assert record["group"] == "corruption" and record["corruption"]["alpha"] == 0.25


def test_the_paper_sweep_has_every_corruption_point():
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "paper.yaml")
    points = {(s.corruption["channel"], s.corruption["alpha"]) for s in sweep.configs.values() if s.corruption}
    assert points == {(c, a) for c in ("vision", "proprio") for a in (0.25, 0.5, 0.75, 1.0)}


def test_the_full_scale_reading_run_is_table_2_with_only_the_reading_changed(tmp_path):
    """configs/sweeps/libero_object_reading_full.yaml: Table 2's settings (by `extends`), its training command with
    only the two reading fields added, and every evaluation of Table 2's seed-0 / seeds-1-2 / reset / A4 / A5 protocol
    mirrored with the same episodes, overrides and pairing."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    table2, full = (Sweep.load(sweeps / f) for f in ("libero_object_table2.yaml", "libero_object_reading_full.yaml"))
    assert full.settings == table2.settings
    ours = Runner(full, tmp_path / "full").train_command(full.configs["predvla_reading"], "libero_object", 0)
    theirs = Runner(table2, tmp_path / "t2").train_command(table2.configs["predvla_table2"], "libero_object", 0)
    differ = differing_flags(ours, theirs)
    assert differ == {"--policy.posteriors_fit_actions", "--policy.open_loop_weight", "--output_dir", "--job_name"}
    assert {"--policy.posteriors_fit_actions=false", "--policy.open_loop_weight=1.0"} <= set(ours)

    def ours_of(name: str | None) -> str | None:
        return name and name.replace("predvla_table2", "predvla_reading")

    for name, spec in full.configs.items():
        twin = table2.configs[name.replace("predvla_reading", "predvla_table2")]
        for field in ("eval_overrides", "eval_args", "n_episodes", "seeds", "init_states", "eval_seed", "group"):
            assert getattr(spec, field) == getattr(twin, field), (name, field)
        assert (spec.checkpoint_from, spec.compare_to, spec.pool_with) == tuple(
            ours_of(x) for x in (twin.checkpoint_from, twin.compare_to, twin.pool_with)), name


PLACED = "_placed_resets"  # D3's evaluations from randomised resets with placements shifted as its demonstrations'


def test_the_demonstration_screens_differ_only_in_their_dataset(tmp_path):
    """The three screens of docs/research/demonstrations.md: the same policies, modes and evaluation sets (D3 also
    its `*_placed_resets`); the teleop ones reach `predvla demos` with their style, diversity and placement spread,
    the scripted one with Table 2's command (no style flags)."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    loaded = {name: Sweep.load(sweeps / f"libero_object_demos_{name}.yaml")
              for name in ("scripted", "teleop", "teleop_placed")}
    shared = [{n: c for n, c in s.configs.items() if PLACED not in n} for s in loaded.values()]
    assert len({tuple(sorted(configs)) for configs in shared}) == 1
    assert len({repr(configs) for configs in shared}) == 1
    assert not any(PLACED in n for s in (loaded["scripted"], loaded["teleop"]) for n in s.configs)
    commands = {}
    for name, sweep in loaded.items():
        spec = sweep.settings.data["libero_object"]
        spec.hdf5, spec.frontend = str(tmp_path / name / "hdf5"), str(tmp_path / name / "frontend")
        sweep.settings.datasets["libero_object"]["root"] = str(tmp_path / name / "dataset")
        commands[name] = dict(Runner(sweep, tmp_path).data_commands("libero_object"))["demos.tasks0"]
    assert "--style" not in commands["scripted"] and "--placement-spread-cm" not in commands["scripted"]
    assert commands["teleop"][commands["teleop"].index("--style") + 1] == "teleop"
    assert commands["teleop"][commands["teleop"].index("--diversity") + 1] == "1.0"
    assert "--placement-spread-cm" not in commands["teleop"]
    placed = commands["teleop_placed"]
    assert placed[placed.index("--placement-spread-cm") + 1] == "3.0" and "--style" in placed
    table2 = Sweep.load(sweeps / "libero_object_table2.yaml").settings.data["libero_object"]
    scripted = loaded["scripted"].settings.data["libero_object"]
    assert {k: v for k, v in vars(scripted).items() if k not in ("hdf5", "frontend")} == \
        {k: v for k, v in vars(table2).items() if k not in ("hdf5", "frontend")}


def test_d3_is_also_evaluated_from_resets_placed_like_its_demonstrations(tmp_path):
    """Every `*_resets` evaluation of D3 has its `*_placed_resets` twin: the same checkpoint, mode, seed and pairing,
    plus `--env.placement_spread_cm=3` (the demonstrations' 3 cm)."""
    sweep = Sweep.load(Path(__file__).parents[1] / "configs" / "sweeps" / "libero_object_demos_teleop_placed.yaml")
    assert sweep.settings.data["libero_object"].placement_spread == 3.0

    def twin(name: str | None) -> str | None:
        return None if name is None else name.replace("_resets", PLACED)

    resets = [n for n in sweep.configs if n.endswith("_resets") and PLACED not in n]
    assert sorted(twin(n) for n in resets) == sorted(n for n in sweep.configs if PLACED in n) and len(resets) == 8
    for name in resets:
        spec, placed = sweep.configs[name], sweep.configs[twin(name)]
        assert placed.eval_args == [*spec.eval_args, "--env.placement_spread_cm=3"], name
        assert placed.compare_to == twin(spec.compare_to) and placed.label.startswith(spec.label), name
        assert {k: v for k, v in vars(placed).items() if k not in ("name", "label", "eval_args", "compare_to")} == \
            {k: v for k, v in vars(spec).items() if k not in ("name", "label", "eval_args", "compare_to")}, name
        assert not placed.init_states and placed.eval_seed == 3000
    command = Runner(sweep, tmp_path).eval_command(Run("olt_open_loop_placed_resets", "libero_object", 0),
                                                   tmp_path / "ckpt", tmp_path / "out", [])
    assert arg(command, "env.init_states") == "false" and arg(command, "seed") == "3000"
    assert arg(command, "env.placement_spread_cm") == "3" and arg(command, "env.render_interval") == "100000"


@pytest.mark.parametrize("dataset, chosen", [("teleop", ("olt", "B2")), ("teleop_placed", ("table2", "B1"))])
def test_a_full_scale_run_file_is_its_screen_restricted_to_the_chosen_cells(dataset, chosen):
    """D2's and D3's full-scale files (demonstrations.md, "Decision rules for full scale"): the screen's dataset and
    data stage, its entries of the chosen PredVLA recipe and BC only, unchanged but for the BC's 50,000 steps and its
    pairing with the chosen PredVLA's open loop; 30,000 steps, 20 episodes on all ten tasks, published apart."""
    sweeps = Path(__file__).parents[1] / "configs" / "sweeps"
    screen = Sweep.load(sweeps / f"libero_object_demos_{dataset}.yaml")
    full = Sweep.load(sweeps / f"libero_object_demos_{dataset}_full.yaml")
    predvla, bc = chosen

    def of(name: str, recipe: str) -> bool:
        return name == recipe or name.startswith(f"{recipe}_")

    assert sorted(full.configs) == sorted(n for n in screen.configs if of(n, predvla) or of(n, bc))
    for name, spec in full.configs.items():
        expected = dict(vars(screen.configs[name]))
        if of(name, bc):
            expected["compare_to"] = expected["compare_to"].replace("olt_", f"{predvla}_", 1)
            expected["steps"] = 50000 if name == bc else None
        assert vars(spec) == expected, name
    differing = {k for k, v in vars(full.settings).items() if k != "data" and v != getattr(screen.settings, k)}
    assert differing == {"steps", "n_episodes", "eval_tasks", "publish"}
    assert (full.settings.steps, full.settings.n_episodes, full.settings.eval_tasks) == (30000, 20, list(range(10)))
    assert full.settings.publish == screen.settings.publish.replace(f"/{dataset}/", f"/{dataset}_full/")
    assert {k: vars(v) for k, v in full.settings.data.items()} == {k: vars(v) for k, v in screen.settings.data.items()}


def test_the_four_suite_sweep_fits_one_front_end_on_all_four_suites(tmp_path):
    """libero_four_suites.yaml: Table 2's data settings for every suite, one front end fitted on all four suites'
    demonstrations (libero_object's read where Table 2's data stage made them), each suite converted with it."""
    configs = Path(__file__).parents[1] / "configs" / "sweeps"
    sweep = Sweep.load(configs / "libero_four_suites.yaml")
    table2 = Sweep.load(configs / "libero_object_table2.yaml").settings.data["libero_object"]
    suites = ["libero_spatial", "libero_object", "libero_goal", "libero_10"]
    assert sweep.settings.suites == suites and sweep.settings.seeds == [0] and sweep.settings.steps == 30000
    for suite in suites:
        data = sweep.settings.data[suite]
        assert data.frontend_from == suites and data.frontend.endswith("outputs/libero_four_suites/frontend")
        same = ("per_task", "render_interval", "demo_seed", "init_noise", "half_turn", "hold_steps", "style",
                "image_storage", "frontend_threads", "vision_weights", "language_from", "frame_stride")
        assert {k: getattr(data, k) for k in same} == {k: getattr(table2, k) for k in same}
    assert sweep.settings.data["libero_object"].hdf5 == table2.hdf5
    runner = Runner(sweep, tmp_path)
    stages = dict(runner.data_commands("libero_spatial"))
    fit = stages["frontend"]
    assert fit[fit.index("--suites") + 1] == ",".join(suites)
    assert [fit[i + 1] for i, a in enumerate(fit) if a == "--hdf5-root"] == [
        str(runner.sweep_path(sweep.settings.data[s].hdf5)) for s in ("libero_spatial", "libero_object")]
    assert {c[c.index("--suite") + 1] for s, c in stages.items() if s.startswith("demos")} == set(suites)
    train = {s: runner.train_command(sweep.configs["olt"], s, 0) for s in suites}
    assert "--policy.open_loop_weight=1.0" in train["libero_object"]
    assert "--policy.posteriors_fit_actions=false" in train["libero_object"]
    assert "--policy.sequence_length=500" in train["libero_10"] and "--policy.tau=[30,14,8,2]" in train["libero_10"]
    assert "--policy.sequence_length=300" in train["libero_goal"]
    assert not any("sequence_length" in a for a in train["libero_spatial"] + train["libero_object"])
    language = sweep.configs["olt_open_loop_other_instruction"]
    assert "--env.instruction_shift=1" in language.eval_args and language.compare_to == "olt_open_loop"
    assert sweep.configs["B1"].lr_sweep.rates == [0.0001, 0.0003, 0.001, 0.003]
    assert sweep.steps_of(sweep.configs["B2"]) == 50000
