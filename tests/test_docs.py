"""The documentation against what it documents: the generated headline against the committed reports, the shipped
checkpoints' configs against the machine, and every command block against the `predvla` CLI and the Makefile."""

import importlib
import json
import re
import shlex
import shutil
from pathlib import Path

import pytest

from lerobot_predvla.cli.main import build_parser
from lerobot_predvla.cli.main import main as predvla_main
from lerobot_predvla.hub.upload import shipped_checkpoints, without_machine_paths
from lerobot_predvla.report.formatting import row_numbers
from lerobot_predvla.report.headline import (
    EXPERIMENTS,
    HEADLINE_END,
    HEADLINE_START,
    README,
    RESULTS_DOC,
    update_docs,
)
from lerobot_predvla.report.results import ReportError
from lerobot_predvla.utils.io import atomic_write_json

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / README, *sorted((REPO / "docs").glob("*.md")), *sorted((REPO / "docs/research").glob("*.md"))]


README_MAX_LINES = 200


def test_readme_is_short_and_starts_with_the_demo_and_the_tests():
    """The README stays a front page (reference material lives in docs/), and its first commands are the two a
    newcomer runs: `make demo`, then `make test`."""
    text = (REPO / README).read_text()
    lines = len(text.splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; move reference material to docs/"
    first_block = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1)
    commands = [line.split("#")[0].split() for line in first_block.splitlines() if line.split("#")[0].strip()]
    assert commands == [["make", "demo"], ["make", "test"]]


def test_the_readme_keeps_room_for_the_four_suite_table(tmp_path):
    """Once results/libero_four_suites/report.json exists the headline adds a table of the four suites (every
    configuration of the sweep file a row); the README must stay short with it."""
    from lerobot_predvla.sweep import Sweep

    shutil.copytree(REPO, tmp_path / "repo", ignore=shutil.ignore_patterns(".git", ".venv", "outputs", "runs"))
    root = tmp_path / "repo"
    for exp in {e.results for e in EXPERIMENTS}:  # the rows read their run records
        if (REPO / "results" / exp / "runs/records").is_dir():
            shutil.copytree(REPO / "results" / exp / "runs/records", root / "results" / exp / "runs/records")
    cell = {"mean": 50.0, "std": None, "n": 1, "planned": 1, "seeds": {"0": 50.0}, "missing_seeds": []}
    sweep = Sweep.load(REPO / "configs/sweeps/libero_four_suites.yaml")
    atomic_write_json(root / "results/libero_four_suites/report.json", {"configs": {
        name: {"label": spec.label, "suites": dict.fromkeys(sweep.settings.suites, cell), "mean3": 50.0, "mean4": 50.0}
        for name, spec in sweep.configs.items()}})
    update_docs(root)
    text = (root / README).read_text()
    assert "All four suites" in text
    assert len(text.splitlines()) <= README_MAX_LINES - 10, "README.md: keep ten lines free for new headline rows"


def _block(path: Path) -> str:
    text = path.read_text()
    return text[text.index(HEADLINE_START):text.index(HEADLINE_END)]


# ----- the headline ----------------------------------------------------------------------------------------
def test_readme_and_results_headline_match_the_committed_reports():
    assert update_docs(REPO, check=True) == [], "run `predvla report --docs` and commit README.md, docs/results.md"
    assert predvla_main(["report", "--docs", "--check", "--root", str(REPO)]) == 0


def test_headline_cells_are_the_report_json_seeds():
    """Each cell against report.json read here directly: single seeds say n = 1, never ± 0."""
    summary = json.loads((REPO / "results/libero_object_cpu/report.json").read_text())
    cells = {name: summary["configs"][name]["suites"]["libero_object"] for name in ("predvla_cpu_8k", "B2")}
    rows = _block(REPO / RESULTS_DOC).splitlines()
    row = next(line for line in rows if "results/libero_object_cpu/report.md" in line)
    for cell in cells.values():
        assert cell["n"] == 1
        assert f"| {cell['mean']:.1f} (n = 1) |" in row
    for path in (REPO / README, REPO / RESULTS_DOC):
        assert "± 0.0" not in _block(path) and "± 0.00" not in _block(path)
    seeds = {}  # the lambda_q = 100 row: seed 0 and the seeds 1-2 that pool with it (pool_with)
    wrist = json.loads((REPO / "results/libero_object_cpu_init_noise_wrist/report.json").read_text())["configs"]
    for name in ("predvla_cpu_8k_lambda_q100_er_lambda_q1_full", "predvla_cpu_8k_lambda_q100_seeds_er_lambda_q1"):
        seeds.update(wrist[name]["suites"]["libero_object"]["seeds"])
    mean = sum(seeds.values()) / len(seeds)
    assert len(seeds) == 3
    assert f"{mean:.1f} ± " in _block(REPO / RESULTS_DOC) and f"(n = {len(seeds)})" in _block(REPO / RESULTS_DOC)


def test_departures_are_one_table_of_the_rows_they_apply_to():
    """Each departure from the paper once, with the numbers of the rows it applies to; docs/results.md adds what it
    departs from, which the README leaves to it, listing its departures one line per topic."""
    readme, results = _block(REPO / README), _block(REPO / RESULTS_DOC)
    assert "| benchmark | libero_object only (all rows) |" in readme and "(the paper:" not in readme
    topics = [line.split(" | ")[0] for line in readme[readme.index("|  | departures |"):].splitlines()[2:]
              if line.startswith("| ")]
    assert len(topics) == len(set(topics)) and "| training" in topics, topics
    assert "| benchmark | libero_object only | the paper: four suites | all |" in results
    assert "| step cap | 280 | the paper: 600 | 3-7 |" in results
    assert "|  | lambda_q = 100 | Table 2: 1 | 6, 7 |" in results
    assert readme.count("| 2. [Table 2]") == 1 and readme.count("| 1. [fit_sensory_olt]") == 1
    assert [row_numbers(n, 6) for n in ([1, 5], [2, 3, 4, 6], [2, 3], list(range(1, 7)))] == [
        "1, 5", "2-4, 6", "2, 3", "all"]


def _record(config: str, seed: int, successes: int, episodes: int = 500) -> dict:
    return {"config": config, "suite": "libero_object", "seed": seed, "successes": successes, "episodes": episodes,
            "n_episodes_per_task": episodes // 10, "episode_length": 600, "init_states": True}


def test_a_new_experiment_leads_the_headline_once_its_report_exists(tmp_path):
    """The Table 2 row appears first as soon as results/libero_object_table2/report.json exists, with the seeds of
    the configurations that pool with its columns' (`pool_with`, as report.json lists them). The CPU recipe's row is
    on docs/results.md only: the README numbers its own rows and says which it left out."""
    for name in ("configs", "results/libero_object_cpu/runs/records"):
        shutil.copytree(REPO / name, tmp_path / name)
    shutil.copy(REPO / "results/libero_object_cpu/report.json", tmp_path / "results/libero_object_cpu/report.json")
    (tmp_path / "docs").mkdir()
    for name in (README, RESULTS_DOC):
        (tmp_path / name).write_text(f"intro\n{HEADLINE_START}\n{HEADLINE_END}\nend\n")
    assert [p.name for p in update_docs(tmp_path)] == ["README.md", "results.md"]
    before = _block(tmp_path / RESULTS_DOC)
    assert "results/libero_object_cpu/report.md" in before and "libero_object_table2" not in before
    readme = _block(tmp_path / README)
    assert "libero_object_cpu/report.md" not in readme and "The paper reports" not in readme  # no row of its own
    assert "Row 1 of [docs/results.md](docs/results.md#libero-libero_object-against-the-paper) (CPU recipe)" in readme

    table2 = tmp_path / "results/libero_object_table2"
    runs = {("predvla_table2", 0): 400, ("predvla_table2_seeds", 1): 300, ("predvla_table2_seeds", 2): 350,
            ("predvla_table2_open_loop", 0): 380}
    configs = {}
    for (config, seed), successes in runs.items():
        atomic_write_json(table2 / f"runs/records/{config}/libero_object/seed{seed}.json",
                          _record(config, seed, successes))
        configs.setdefault(config, {"suites": {"libero_object": {"seeds": {}}}})
        configs[config]["suites"]["libero_object"]["seeds"][str(seed)] = successes / 5
    atomic_write_json(table2 / "report.json", {"configs": configs, "pooled": {
        "predvla_table2": {"configs": ["predvla_table2", "predvla_table2_seeds"]}}})
    update_docs(tmp_path)
    rows = [line for line in _block(tmp_path / RESULTS_DOC).splitlines() if re.match(r"\| \d+\. \[", line)]
    assert rows[0].startswith("| 1. [") and "results/libero_object_table2/report.md" in rows[0]
    assert "| 70.0 ± 10.0 (n = 3) | 76.0 (n = 1) | — | — |" in rows[0]  # (80 + 60 + 70) / 3; open loop seed 0
    assert "libero_object_cpu/report.md" in rows[1] and rows[1].startswith("| 2. [")
    readme = _block(tmp_path / README)
    assert [line[:5] for line in readme.splitlines() if re.match(r"\| \d+\. \[", line)] == ["| 1. "]
    assert "Row 2 of [docs/results.md]" in readme and "ahead of exact open loop in 0 of 1 rows" in readme
    assert update_docs(tmp_path, check=True) == []
    # The sentence under the table counts the rows whose better BC baseline leads PredVLA: the CPU row's BC-RNN
    # (85.5 against 72.0), then also Table 2's BC-Transformer once its record exists (98.0 against 70.0).
    assert "the better BC baseline is ahead of it in 1 of the 1 rows where one was trained" in _block(
        tmp_path / RESULTS_DOC)
    atomic_write_json(table2 / "runs/records/B1/libero_object/seed0.json", _record("B1", 0, 490))
    configs["B1"] = {"suites": {"libero_object": {"seeds": {"0": 98.0}}}}
    atomic_write_json(table2 / "report.json", {"configs": configs, "pooled": {
        "predvla_table2": {"configs": ["predvla_table2", "predvla_table2_seeds"]}}})
    update_docs(tmp_path)
    assert "| 70.0 ± 10.0 (n = 3) | 76.0 (n = 1) | — | 98.0 (n = 1) |" in _block(tmp_path / README)
    assert "the better BC baseline is ahead of it in 2 of the 2 rows where one was trained" in _block(
        tmp_path / RESULTS_DOC)
    assert "the better BC baseline is ahead of it in 1 of the 1 rows where one was trained" in _block(
        tmp_path / README)


def test_a_row_without_baselines_shows_those_of_the_row_with_its_demonstrations(tmp_path):
    """The full-scale reading trains no BC baseline: its row leads and shows Table 2's B1 and B2, which trained on
    the same dataset; a sweep file that made another dataset is refused, naming the file and the key."""
    shutil.copytree(REPO / "configs", tmp_path / "configs")
    table2 = Path("results/libero_object_table2")
    shutil.copytree(REPO / table2 / "runs/records", tmp_path / table2 / "runs/records")
    shutil.copy(REPO / table2 / "report.json", tmp_path / table2 / "report.json")
    reading = tmp_path / "results/libero_object_reading"
    runs = {("predvla_reading", 0): 430, ("predvla_reading_open_loop", 0): 410}
    configs = {}
    for (config, seed), successes in runs.items():
        atomic_write_json(reading / f"runs/records/{config}/libero_object/seed{seed}.json",
                          _record(config, seed, successes))
        configs[config] = {"suites": {"libero_object": {"seeds": {str(seed): successes / 5}}}}
    atomic_write_json(reading / "report.json", {"configs": configs})
    (tmp_path / "docs").mkdir()
    for name in (README, RESULTS_DOC):
        (tmp_path / name).write_text(f"intro\n{HEADLINE_START}\n{HEADLINE_END}\nend\n")
    update_docs(tmp_path)
    baselines = json.loads((REPO / table2 / "report.json").read_text())["configs"]
    rnn, transformer = (baselines[name]["suites"]["libero_object"]["mean"] for name in ("B2", "B1"))
    rows = [line for line in _block(tmp_path / README).splitlines() if re.match(r"\| \d+\. \[", line)]
    assert "results/libero_object_reading/report.md" in rows[0] and "results/libero_object_table2/report.md" in rows[1]
    assert f"| 86.0 (n = 1) | 82.0 (n = 1) | {rnn:.1f} (n = 1) | {transformer:.1f} (n = 1) |" in rows[0]
    assert "BC baselines: [Table 2's](results/libero_object_table2/report.md)" in rows[0]
    sweeps = tmp_path / "configs/sweeps"
    base = (sweeps / "libero_object_table2.yaml").read_text()
    (sweeps / "other_data.yaml").write_text(base.replace("per_task: 50", "per_task: 20"))
    reading_sweep = sweeps / "libero_object_reading_full.yaml"
    reading_sweep.write_text(reading_sweep.read_text().replace("extends: libero_object_table2.yaml",
                                                               "extends: other_data.yaml"))
    with pytest.raises(ReportError, match=r"libero_object_reading_full.yaml: `data.libero_object` differs"):
        update_docs(tmp_path)


def test_a_row_of_teleop_demonstrations_names_its_data_its_tasks_and_its_own_blind_replay(tmp_path):
    """The teleoperator model's demonstrations with varied placements get rows of their own: the dataset, the three
    screened tasks as a departure, and one of its demonstrations replayed blind on the same official init states
    (states 1-9 and the plan's own start, state 0), which must be the starts the row's cells ran from."""
    shutil.copytree(REPO / "configs", tmp_path / "configs")
    blind = Path("results/demonstrations/blind_replay/E1_teleop/report.json")
    (tmp_path / blind).parent.mkdir(parents=True)
    shutil.copy(REPO / blind, tmp_path / blind)
    tasks = json.loads((REPO / blind).read_text())["libero_object"]
    replayed = sum(t["successes"] + t["source_replay_success"] for t in tasks.values())
    results = tmp_path / "results/demonstrations/teleop_placed"
    runs = {"olt": (4, 5, 6), "olt_open_loop": (5, 5, 6), "B1": (9, 9, 8), "B2": (7, 9, 8)}

    def write(episodes_per_task: int) -> None:
        configs = {}
        for config, successes in runs.items():
            record = {**_record(config, 0, sum(successes), 3 * episodes_per_task),
                      "n_episodes_per_task": episodes_per_task, "eval_tasks": [2, 3, 6],
                      "tasks": {str(t): {"successes": s, "episodes": episodes_per_task}
                                for t, s in zip((2, 3, 6), successes, strict=True)}}
            atomic_write_json(results / f"runs/records/{config}/libero_object/seed0.json", record)
            configs[config] = {"suites": {"libero_object": {"seeds": {"0": 100 * sum(successes) / 30}}}}
        atomic_write_json(results / "report.json", {"configs": configs})

    write(10)
    (tmp_path / "docs").mkdir()
    for name in (README, RESULTS_DOC):
        (tmp_path / name).write_text(f"intro\n{HEADLINE_START}\n{HEADLINE_END}\nend\n")
    update_docs(tmp_path)
    readme = _block(tmp_path / README)
    row = next(line for line in readme.splitlines() if line.startswith("| 1. ["))
    assert ("50 teleoperator-model demonstrations per task (diversity 1), placements varied by 3 cm, arm start "
            "noise, one wrist branch") in row
    assert f"replayed blind on the same starts: {100 * replayed / 30:.1f} ({replayed}/30)" in row
    assert "| 50.0 (n = 1) | 53.3 (n = 1) | 80.0 (n = 1) | 86.7 (n = 1) |" in row
    assert "| evaluation tasks | 2, 3, 6 (all rows) |" in readme
    assert "objects moved from LIBERO's placements by 3 cm (std per axis)" in readme
    write(20)  # official init states 0-19: not the starts the blind replay ran on
    with pytest.raises(ReportError, match=r"E1_teleop/report.json: replays tasks \[2, 3, 6\] on states"):
        update_docs(tmp_path)


def test_the_four_suites_join_the_headline_beside_the_papers_table_3_once_their_report_exists(tmp_path):
    """The four-suite sweep's report adds one table to both headline blocks: the paper's Table 3 and Table 6 (A6)
    rows, one demonstration replayed blind per suite, then the sweep's configurations per suite, with 3-suite
    (spatial, goal, object) and 4-suite means only where every suite they average has a value. The libero_object
    rows, whose front end is fitted on libero_object alone, list that as a departure."""
    for name in ("configs", "results/libero_object_cpu/runs/records", "results/blind_replay"):
        shutil.copytree(REPO / name, tmp_path / name)
    shutil.copy(REPO / "results/libero_object_cpu/report.json", tmp_path / "results/libero_object_cpu/report.json")
    (tmp_path / "docs").mkdir()
    for name in (README, RESULTS_DOC):
        (tmp_path / name).write_text(f"intro\n{HEADLINE_START}\n{HEADLINE_END}\nend\n")
    update_docs(tmp_path)
    assert "All four suites" not in _block(tmp_path / README)  # no four-suite report yet: libero_object alone
    # libero_object's rows keep a front end of their own, and say so.
    assert ("| PCA bases fitted on libero_object's demonstrations only | the paper: fitted jointly on the four "
            "suites' training demonstrations | all |") in _block(tmp_path / RESULTS_DOC)

    def cell(*rates: float) -> dict:
        return {"mean": sum(rates) / len(rates), "std": None if len(rates) == 1 else 5.0, "n": len(rates),
                "planned": len(rates), "seeds": {str(i): r for i, r in enumerate(rates)}, "missing_seeds": []}

    suites = {"libero_spatial": cell(60.0), "libero_goal": cell(70.0), "libero_object": cell(80.0)}
    atomic_write_json(tmp_path / "results/libero_four_suites/report.json", {"configs": {
        "olt": {"label": "PredVLA fit_sensory_olt, Table 2 ER", "suites": suites, "mean3": 70.0, "mean4": None},
        "B2": {"label": "BC-RNN (B2)", "suites": {**suites, "libero_10": cell(20.0)}, "mean3": 70.0,
               "mean4": 57.5}}})
    assert [p.name for p in update_docs(tmp_path)] == ["README.md", "results.md"]
    block = _block(tmp_path / README)
    lines = block[block.index("All four suites"):].splitlines()
    assert "| LIBERO success (%), mean ± std over training seeds | spatial | goal | object | long | 3-suite mean " \
           "| 4-suite mean |" in lines
    # The paper's PredVLA: (83.19 + 88.40 + 89.24) / 3 and with long's 40.57 / 4, the paper's 86.9 and 75.4.
    assert ("| paper: PredVLA, error regression (Table 3, 14 seeds) | 83.19 ± 6.10 | 88.40 ± 3.83 | 89.24 ± 6.13 "
            "| 40.57 ± 6.44 | 86.94 | 75.35 |") in lines
    assert "| paper: PredVLA, exact open loop (Table 6, A6, 7 seeds) | 73.79 ± 4.38 | 78.50 ± 9.14 |" in block
    blind = json.loads((REPO / "results/blind_replay/report.json").read_text())
    s, n = (sum(t[k] for t in blind["libero_goal"].values()) for k in ("successes", "episodes"))
    row = next(line for line in lines if line.startswith("| reference, not a policy"))
    assert f"| {100 * s / n:.1f} ({s}/{n}) |" in row
    assert "| this project: PredVLA fit_sensory_olt, Table 2 ER | 60.00 (n = 1) | 70.00 (n = 1) | 80.00 (n = 1) " \
           "| — | 70.00 | — |" in lines
    assert "| this project: BC-RNN (B2) | 60.00 (n = 1) | 70.00 (n = 1) | 80.00 (n = 1) | 20.00 (n = 1) | 70.00 " \
           "| 57.50 |" in lines
    assert "results/libero_four_suites/report.md" in block and "../results/libero_four_suites/report.md" in _block(
        tmp_path / RESULTS_DOC)
    assert update_docs(tmp_path, check=True) == []


def test_check_fails_and_names_the_file_when_a_number_is_edited(tmp_path, capsys):
    shutil.copytree(REPO / "configs", tmp_path / "configs")
    for exp in {e.results for e in EXPERIMENTS}:
        if (REPO / "results" / exp / "report.json").is_file():
            shutil.copytree(REPO / "results" / exp / "runs/records", tmp_path / "results" / exp / "runs/records")
            shutil.copy(REPO / "results" / exp / "report.json", tmp_path / "results" / exp / "report.json")
    # the reference row (`predvla blind-replay`) and the rows' own blind replays
    for blind in {Path("results/blind_replay"), *(Path("results") / e.blind_replay for e in EXPERIMENTS
                                                   if e.blind_replay)}:
        if (REPO / blind / "report.json").is_file():
            (tmp_path / blind).mkdir(parents=True, exist_ok=True)
            shutil.copy(REPO / blind / "report.json", tmp_path / blind / "report.json")
    (tmp_path / "docs").mkdir()
    shutil.copy(REPO / README, tmp_path / README)
    shutil.copy(REPO / RESULTS_DOC, tmp_path / RESULTS_DOC)
    readme = tmp_path / README
    text = readme.read_text()
    assert "| 87.8 (n = 1) |" in text  # row 1's exact open loop
    readme.write_text(text.replace("| 87.8 (n = 1) |", "| 88.8 (n = 1) |", 1))
    assert predvla_main(["report", "--docs", "--check", "--root", str(tmp_path)]) == 1
    assert "README.md: differs" in capsys.readouterr().err


# ----- shared configs do not pin the training machine's device ---------------------------------------------
SHIPPED = [path.relative_to(REPO / "checkpoints").as_posix() for path in shipped_checkpoints(REPO)]


@pytest.fixture
def best_device_cuda(monkeypatch):
    """A machine whose best device is CUDA, as LeRobot's configs see it: a stored device that is available is kept,
    a missing one becomes the best available."""
    import torch
    from lerobot.configs import policies

    monkeypatch.setattr(policies, "auto_select_torch_device", lambda: torch.device("cuda"))
    monkeypatch.setattr(policies, "is_torch_device_available", lambda device: device in ("cpu", "cuda"))


@pytest.mark.parametrize("checkpoint", SHIPPED)
def test_shipped_checkpoint_configs_leave_the_device_unset(checkpoint):
    path = REPO / "checkpoints" / checkpoint
    assert json.loads((path / "config.json").read_text())["device"] is None
    assert json.loads((path / "train_config.json").read_text())["policy"]["device"] is None


def test_shipped_checkpoint_follows_the_machine(best_device_cuda):
    """`config.json` (`--policy.path`, `from_pretrained`) and `train_config.json` (`lerobot-train --config_path=...`)
    loaded by LeRobot on a machine whose best device is CUDA: the shipped checkpoint runs and trains there."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.configs.train import TrainPipelineConfig

    path = REPO / "checkpoints/predvla_libero_object"
    assert PreTrainedConfig.from_pretrained(path).device == "cuda"
    assert TrainPipelineConfig.from_pretrained(path).policy.device == "cuda"


@pytest.mark.parametrize("checkpoint", SHIPPED)
def test_shipped_checkpoint_processors_follow_the_policy(checkpoint):
    """Loaded as `lerobot-eval` loads them (the preprocessor's device step replaced by the policy's device), the
    processors move the inputs to the policy's device and the actions to the CPU (the environment's); the front-end
    step records no device (its encoders follow the images)."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.processor import DeviceProcessorStep

    from lerobot_predvla.hub.card import FRONTEND_STEP, PREPROCESSOR_FILE

    path = REPO / "checkpoints" / checkpoint
    steps = json.loads((path / PREPROCESSOR_FILE).read_text())["steps"]
    assert all("device" not in s["config"] for s in steps if s["registry_name"] == FRONTEND_STEP)
    config = PreTrainedConfig.from_pretrained(path)
    pre, post = make_pre_post_processors(config, pretrained_path=str(path),
                                         preprocessor_overrides={"device_processor": {"device": config.device}})
    assert [s.device for s in pre.steps if isinstance(s, DeviceProcessorStep)] == [config.device]
    assert [s.device for s in post.steps if isinstance(s, DeviceProcessorStep)] == ["cpu"]


def test_push_clears_the_training_machine(tmp_path):
    config, train, pre = tmp_path / "config.json", tmp_path / "train_config.json", tmp_path / "policy_preprocessor.json"
    artefact = tmp_path / "frontend.json"
    fit = {"hdf5_root": "/data/hdf5", "suites": ["libero_object"], "num_demos": 500}  # an artefact before by_suite
    config.write_text(json.dumps({"type": "predvla", "device": "cuda", "frontend_dir": "/data/frontend",
                                  "pretrained_path": "/runs/x/checkpoints/last/pretrained_model"}))
    train.write_text(json.dumps({"policy": {"type": "predvla", "device": "cpu", "pretrained_path": "/runs/x/p"},
                                 "output_dir": "/runs/x", "checkpoint_path": "/runs/x/checkpoints/last"}))
    steps = [{"registry_name": "predvla_frontend_processor",
              "config": {"artefact": {"format": "predvla-frontend", "fit": dict(fit)}, "device": "cpu"}},
             {"registry_name": "device_processor", "config": {"device": "cpu", "float_dtype": None}}]
    pre.write_text(json.dumps({"name": "policy_preprocessor", "steps": steps}))
    artefact.write_text(json.dumps({"format": "predvla-frontend", "fit": dict(fit)}))
    published = without_machine_paths({"config.json": config, "train_config.json": train,
                                       "policy_preprocessor.json": pre, "predvla_frontend/frontend.json": artefact})
    assert json.loads(published["config.json"]) == {"type": "predvla", "device": None, "frontend_dir": None,
                                                    "pretrained_path": None}
    train_config = json.loads(published["train_config.json"])
    assert train_config["policy"]["device"] is None and train_config["policy"]["pretrained_path"] is None
    assert train_config["output_dir"] is None and train_config["checkpoint_path"] is None
    cleared = {**fit, "hdf5_root": None}  # what the bases were fitted on stays; where it lay does not
    assert [s["config"] for s in json.loads(published["policy_preprocessor.json"])["steps"]] == [
        {"artefact": {"format": "predvla-frontend", "fit": cleared}},
        {"device": "cpu", "float_dtype": None}]  # LeRobot's loaders replace the device step's
    assert json.loads(published["predvla_frontend/frontend.json"])["fit"] == cleared
    # A joint fit's folders, one per suite, are cleared too.
    joint = {"hdf5_roots": ["/a", "/b"], "suites": ["libero_object", "libero_goal"],
             "by_suite": {"libero_object": {"hdf5_root": "/a", "num_demos": 500},
                          "libero_goal": {"hdf5_root": "/b", "num_demos": 500}}}
    artefact.write_text(json.dumps({"format": "predvla-frontend", "fit": joint}))
    published = without_machine_paths({"predvla_frontend/frontend.json": artefact})
    assert json.loads(published["predvla_frontend/frontend.json"])["fit"] == {
        "hdf5_roots": None, "suites": ["libero_object", "libero_goal"],
        "by_suite": {"libero_object": {"hdf5_root": None, "num_demos": 500},
                     "libero_goal": {"hdf5_root": None, "num_demos": 500}}}


def absolute_paths(value) -> list[str]:
    """Every string of a parsed JSON document that is an absolute POSIX path."""
    if isinstance(value, dict):
        return [p for v in value.values() for p in absolute_paths(v)]
    if isinstance(value, list):
        return [p for v in value for p in absolute_paths(v)]
    return [value] if isinstance(value, str) and value.startswith("/") else []


@pytest.mark.parametrize("checkpoint", SHIPPED)
def test_shipped_checkpoints_name_no_path_of_the_training_machine(checkpoint):
    path = REPO / "checkpoints" / checkpoint
    found = {f.relative_to(path).as_posix(): absolute_paths(json.loads(f.read_text())) for f in path.rglob("*.json")}
    assert not {name: paths for name, paths in found.items() if paths}
    card = (path / "README.md").read_text()
    assert not [p for paths in found.values() for p in paths if p in card]
    assert "pretrained_path =" not in card  # the card's list of departures names no loading path


def test_shipped_checkpoints_include_the_models_sweeps_publish():
    assert {"predvla_libero_object", "libero_object_table2/predvla_table2_seed1"} <= set(SHIPPED)
    assert all((REPO / "checkpoints" / name / "model.safetensors").is_file() for name in SHIPPED)


@pytest.mark.parametrize("where", ["shipped", "sweep/predvla_seed0"])  # checkpoints/<name>/, a sweep's train.publish
def test_report_docs_rewrites_a_checkpoint_that_pins_the_device_and_keeps_its_manifest(tmp_path, where):
    from lerobot_predvla.hub.upload import stale_checkpoint_files
    from lerobot_predvla.utils.io import atomic_write_bytes
    from lerobot_predvla.utils.manifest import verify_manifests, write_manifest

    checkpoint = tmp_path / "checkpoints" / where
    shutil.copytree(REPO / "checkpoints/predvla_libero_object", checkpoint)
    train = checkpoint / "train_config.json"
    train.write_text(train.read_text().replace('"device": null', '"device": "cpu"'))
    write_manifest(checkpoint)
    weights = (checkpoint / "model.safetensors").read_bytes()
    stale = stale_checkpoint_files(tmp_path)
    assert {checkpoint / "train_config.json", checkpoint / "sha256_manifest.json"} <= set(stale)
    for path, data in stale.items():
        atomic_write_bytes(path, data)
    assert json.loads(train.read_text())["policy"]["device"] is None
    assert verify_manifests(checkpoint) and (checkpoint / "model.safetensors").read_bytes() == weights
    assert stale_checkpoint_files(tmp_path) == {}


# ----- every documented command exists ---------------------------------------------------------------------
def _commands(path: Path) -> list[list[str]]:
    """Shell commands of the ```bash blocks as words: continuation lines joined, comments dropped, split at `&&`,
    `;`, `|` and `&`, environment assignments (OMP_NUM_THREADS=1) and wrappers (time, nice) left out."""
    commands = []
    for block in re.findall(r"```(?:bash|sh|shell)\n(.*?)```", path.read_text(), flags=re.S):
        pending = ""
        for line in re.sub(r"\\\n\s*", " ", block).splitlines():
            lexer = shlex.shlex(pending + line, posix=True, punctuation_chars=";&|")
            lexer.commenters = "#"
            lexer.wordchars += "-./=[],:{}$*~@%+"
            try:
                tokens = list(lexer)
            except ValueError:  # a quoted string goes on on the next line
                pending += line + " "
                continue
            pending, words = "", []
            for token in [*tokens, ";"]:
                if token.strip(";&|"):
                    words.append(token)
                    continue
                while words and (re.match(r"^[A-Z_]+=", words[0]) or words[0] in ("time", "nice", "-n", "10")):
                    words.pop(0)
                if words:
                    commands.append(words)
                words = []
        assert not pending, f"{path}: unterminated quote in a command block: {pending}"
    return commands


def _make_targets() -> set[str]:
    return set(re.findall(r"^([A-Za-z][\w-]*):", (REPO / "Makefile").read_text(), flags=re.M))


def test_every_documented_command_exists():
    parser, targets = build_parser(), _make_targets()
    checked, wrong = 0, []
    for path in DOCS:
        for words in _commands(path):
            command, program = " ".join(words), Path(words[0]).name
            if program == "make":
                wrong += [f"{path.name}: `{command}`: no make target {t}" for t in words[1:] if t not in targets]
                checked += 1
            elif program == "predvla":
                try:
                    parser.parse_args([w for w in words[1:] if w != "..."])
                except SystemExit:
                    wrong.append(f"{path.name}: `{command}` does not parse against `predvla`'s arguments")
                checked += 1
            elif words[:2] == ["python", "-m"] and len(words) > 2 and words[2].startswith("research."):
                try:  # a research command runs from the checkout: its module's (or package's __main__'s) parser
                    module = importlib.import_module(words[2])
                    if not hasattr(module, "build_parser"):
                        module = importlib.import_module(f"{words[2]}.__main__")
                    module.build_parser().parse_args([w for w in words[3:] if w != "..."])
                except (ImportError, AttributeError, SystemExit):
                    wrong.append(f"{path.name}: `{command}` does not parse against {words[2]}'s arguments")
                checked += 1
    assert checked > 20
    assert not wrong, "\n".join(wrong)


BARE_BRACKET = re.compile(r"(^|\s)--[\w.]+=[\[{]")
# Inline code that is a command or a command's argument, as opposed to a quoted message (`zsh: no matches found: ...`).
INLINE_COMMAND = re.compile(r"\s*(--|lerobot-|predvla |python |make |accelerate |torchrun )")


def test_bracket_arguments_are_quoted():
    """zsh expands an unquoted `--x=[0,1]` (bash a `--x={a,b}`); every documented one is quoted, in command blocks
    and in inline commands alike."""
    bare = []
    for path in DOCS:
        text = path.read_text()
        blocks = re.findall(r"```(?:bash|sh|shell)\n(.*?)```", text, flags=re.S)
        bare += [f"{path.name}: {line.strip()}" for block in blocks for line in block.splitlines()
                 if BARE_BRACKET.search(line)]
        inline = re.findall(r"`([^`]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
        bare += [f"{path.name}: `{span}`" for span in inline
                 if INLINE_COMMAND.match(span) and BARE_BRACKET.search(span)]
    assert not bare, "\n".join(bare)


# ----- model cards and configs of the shipped checkpoints -------------------------------------------------
def test_shipped_configs_and_model_cards_are_as_published():
    from lerobot_predvla.hub.upload import stale_checkpoint_files

    assert stale_checkpoint_files(REPO) == {}, "run `predvla report --docs` and commit checkpoints/"


def test_model_card_states_the_checkpoints_own_training_and_results():
    from lerobot_predvla.hub.card import evaluation_records

    checkpoint = REPO / "checkpoints/predvla_libero_object"
    card = (checkpoint / "README.md").read_text()
    config = json.loads((checkpoint / "config.json").read_text())
    train_cfg = json.loads((checkpoint / "train_config.json").read_text())
    frontend = json.loads((checkpoint / "predvla_frontend/frontend.json").read_text())
    assert f"Trained for {train_cfg['steps']:,} steps, batch size {train_cfg['batch_size']}, seed 0." in card
    assert f"optimizer_lr = {config['optimizer_lr']:g} (Table 2: 6e-05)" in card
    assert frontend["vision"]["weights_description"] in card and "RANDOM" in card
    assert "--policy.path=checkpoints/predvla_libero_object " in card and "pip install" not in card
    records = evaluation_records(checkpoint, REPO / "results")
    assert {r["config"] for r in records} >= {"predvla_cpu_8k", "predvla_cpu_8k_open_loop"}
    for record in records:  # every evaluation, with its own totals and protocol
        assert f"`{record['config']}` |" in card and f"{record['successes']}/{record['episodes']}" in card
    assert "No evaluation results" not in card


def test_a_published_copy_of_a_resumed_training_carries_its_evaluations():
    """`checkpoints/predvla_libero_object_reading` is `predvla push --out` of a training that resumed from a
    checkpoint (its record's training command names no job): the card finds its evaluations by the weights' SHA-256,
    and a copy with other weights finds none of them."""
    from lerobot_predvla.hub.card import evaluation_records

    checkpoint = REPO / "checkpoints/predvla_libero_object_reading"
    configs = {r["config"] for r in evaluation_records(checkpoint, REPO / "results")}
    assert {"predvla_reading", "predvla_reading_open_loop"} <= configs
    card = (checkpoint / "README.md").read_text()
    assert "batch size 16 per process, 2 processes (32 per step)" in card and "387/500" in card

    other = REPO / "checkpoints/predvla_libero_object"
    assert not configs & {r["config"] for r in evaluation_records(other, REPO / "results")}


def test_a_longer_training_of_the_same_job_is_another_model():
    """D2's full-scale model (30,000 steps) and its screening model (10,000) share the job name, dataset and seed:
    each card lists only its own evaluations."""
    from lerobot_predvla.hub.card import evaluation_records

    full, screen = (REPO / f"checkpoints/demonstrations/{name}/olt_seed0" for name in ("teleop_full", "teleop"))
    assert json.loads((full / "train_config.json").read_text())["job_name"] == json.loads(
        (screen / "train_config.json").read_text())["job_name"]
    assert {r["results"] for r in evaluation_records(screen, REPO / "results")} == {"results/demonstrations/teleop"}
    assert all(r["results"] == "results/demonstrations/teleop_full"
               for r in evaluation_records(full, REPO / "results"))
    assert "Trained for 30,000 steps, batch size 16 per process" in (full / "README.md").read_text()


def test_model_card_command_reproduces_its_results_and_limitations_state_them():
    """The card's `lerobot-eval` command runs the protocol of the results it shows (episodes per task, step cap), and
    its limitations give error regression against exact open loop and the BC baselines on the same data."""
    from lerobot_predvla.hub.card import evaluation_records

    checkpoint = REPO / "checkpoints/predvla_libero_object"
    card = (checkpoint / "README.md").read_text()
    records = {r["config"]: r for r in evaluation_records(checkpoint, REPO / "results")}
    shown, open_loop = records["predvla_cpu_8k"], records["predvla_cpu_8k_open_loop"]
    command = card[card.index("lerobot-eval --policy.path"):].splitlines()[0]
    protocol = f"--env.episode_length={shown['episode_length']} --eval.n_episodes={shown['n_episodes_per_task']} "
    assert protocol in command
    limitations = card[card.index("## Limitations"):card.index("## Citation")]
    assert (f"Error regression succeeds in {shown['successes']}/{shown['episodes']}" in limitations
            and f"exact open loop (`--policy.er_iterations=0`: {open_loop['successes']}/{open_loop['episodes']}"
            in limitations)
    runs = REPO / "results/libero_object_cpu/runs/records"
    baselines = [json.loads(p.read_text()) for p in runs.glob("B*/*/*.json")]
    assert baselines and all(f"{b['successes']}/{b['episodes']}" in limitations for b in baselines)
    assert "compare across seeds" not in limitations and "one training seed (0)" in limitations


def test_a_shifted_or_varied_evaluation_is_not_the_cards_official_result():
    """D2's full-scale model's shifted evaluations (E3) are never the result a card's command reproduces or its
    limitations state as from the official init states; a record from those states is."""
    from lerobot_predvla.hub.card import evaluation_records, main_record

    checkpoint = REPO / "checkpoints/demonstrations/teleop_full/olt_seed0"
    config = json.loads((checkpoint / "config.json").read_text())
    shifted = [r for r in evaluation_records(checkpoint, REPO / "results") if r.get("object_shift")]
    official = {"config": "olt", "init_states": True, "object_shift": None, "variant": None, "episodes": 200,
                "episode_length": 600}
    assert len(shifted) == 3 and main_record(shifted, config) is None
    assert main_record([*shifted, official], config) is official
    assert main_record([*shifted, {**official, "variant": "libero_pro_object"}], config) is None


def test_push_attaches_the_recorded_evaluations_of_a_shipped_checkpoint(tmp_path):
    """`predvla push --results results` renders the same results as the committed card (one renderer)."""
    card = tmp_path / "card.md"
    checkpoint = REPO / "checkpoints/predvla_libero_object"
    assert predvla_main(["push", str(checkpoint), "me/predvla_libero_object", "--results", str(REPO / "results"),
                         "--dry-run", "--card-out", str(card)]) == 0

    def section(text: str) -> str:
        return text[text.index("## Results"):text.index("## Limitations")]

    assert section(card.read_text()) == section((checkpoint / "README.md").read_text())
    assert "--policy.path=me/predvla_libero_object " in card.read_text()
