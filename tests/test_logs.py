"""Run logs keep their messages and each progress bar's last state, not its every redraw."""

import sys

from lerobot_predvla.sweep import subprocess_executor
from lerobot_predvla.sweep.kill_resume import logged_steps
from lerobot_predvla.sweep.logs import TrainingRun, compact_log, compact_text, main, training_runs
from lerobot_predvla.sweep.lr_selection import heldout_losses

TRAIN_STEP = "INFO 2026-11-26 15:04:59 ot_train.py:641 step:9 smpl:291 ep:2K loss:-14.459 grdn:17.435"
EVAL_LOSS = "INFO 2026-11-26 15:05:01 ot_train.py:702 step 9: eval_loss=0.5120"


def train_bar(step: int, total: int = 200) -> str:
    return f"Training:  {100 * step // total:2d}%|          | {step}/{total} [00:{step:02d}<01:00,  3.06step/s]"


def rollout_bar(step: int) -> str:
    return (f"Running rollout with at most 600 steps:  {step // 6:2d}%|▌         | {step}/600 [00:04<01:01,  9.24it/s, "
            f"running_success_rate=0.0%]\x1b[A")


def test_training_bars_redrawn_after_carriage_returns_keep_the_step_lines():
    """lerobot-train: one line of carriage-return redraws, a logged step glued to the last one."""
    text = "$ lerobot-train --steps=200\n" + "".join(f"\r{train_bar(s)}" for s in range(1, 101)) + TRAIN_STEP + "\n"
    text += "".join(f"\r{train_bar(s)}" for s in range(101, 201)) + "\nINFO done\n"
    compacted = compact_text(text)
    assert compacted == f"$ lerobot-train --steps=200\n{train_bar(100)}{TRAIN_STEP}\n{train_bar(200)}\nINFO done\n"
    assert compact_text(compacted) == compacted


def test_nested_evaluation_bars_keep_their_last_states_and_the_messages_between(tmp_path):
    """lerobot-eval: a fresh line per redraw, blank lines and cursor-up escapes between nested bars."""
    batches = "Stepping through eval batches: {}%|          | {}/5 [00:00<?, ?it/s]"
    lines = ["INFO config", batches.format(0, 0), "", f"{rollout_bar(0)}[predvla] vision encoder: ResNet18"]
    for step in range(1, 601):
        lines += ["", rollout_bar(step)]
    lines += ["", batches.format(20, 1), "", "WARNING something worth reading", "", rollout_bar(1), "", rollout_bar(2),
              "", batches.format(100, 5), "INFO eval_info written", ""]
    log = tmp_path / "seed0.eval.log"
    log.write_text("\n".join(lines))
    saved = compact_log(log)
    assert saved > 0 and log.read_text() == "\n".join([
        "INFO config", batches.format(0, 0), f"{rollout_bar(0)[:-3]}[predvla] vision encoder: ResNet18",
        rollout_bar(600)[:-3], batches.format(20, 1), "WARNING something worth reading", rollout_bar(2)[:-3],
        batches.format(100, 5), "INFO eval_info written", ""])
    assert compact_log(log) == 0


def test_what_the_sweep_reads_from_a_log_is_unchanged(tmp_path):
    """Held-out losses (learning-rate selection) and logged steps (kill-and-resume) parse alike before and after."""
    text = "".join(f"\r{train_bar(s)}" for s in range(1, 50)) + TRAIN_STEP + "\n" + EVAL_LOSS + "\n"
    text += "".join(f"\r{train_bar(s)}" for s in range(50, 99)) + TRAIN_STEP.replace(":9 ", ":18 ") + "\n"
    raw, compacted = tmp_path / "raw.log", tmp_path / "compacted.log"
    raw.write_text(text)
    compacted.write_text(text)
    compact_log(compacted)
    assert compacted.stat().st_size < raw.stat().st_size / 10
    assert heldout_losses(compacted) == heldout_losses(raw) and heldout_losses(raw)
    assert logged_steps(compacted) == logged_steps(raw) == [(9, -14.459), (18, -14.459)]


def test_the_sweep_compacts_a_log_when_its_command_ends(tmp_path):
    log = tmp_path / "logs" / "seed0.train.log"
    script = ("import sys\n"
              "for s in range(1, 201):\n"
              "    sys.stdout.write('\\rTraining: %3d%%|          | %d/200 [00:00<00:00,  3.06step/s]' % (s // 2, s))\n"
              "print()\n"
              "print('INFO done')\n")
    assert subprocess_executor([sys.executable, "-c", script], log) == 0
    lines = log.read_text().splitlines()  # after the command's own lines
    assert lines[-2:] == ["Training: 100%|          | 200/200 [00:00<00:00,  3.06step/s]", "INFO done"]


def test_the_command_line_names_a_missing_path(tmp_path, capsys):
    assert main([str(tmp_path / "nope")]) == 2
    assert "nope: no such file or directory" in capsys.readouterr().err
    (tmp_path / "a.log").write_text("".join(f"\r{train_bar(s)}" for s in range(1, 201)) + "\n")
    assert main([str(tmp_path)]) == 0 and (tmp_path / "a.log").read_text() == train_bar(200) + "\n"


def train_call(first: int, reached: int, steps: int = 30, start: str = "12:00:00", end: str = "12:05:30") -> str:
    """One lerobot-train call as the sweep logs it: its command line, INFO lines, its progress bar's redraws."""
    left = steps - first
    bar = "".join(f"\r{train_bar(s, left)}" for s in range(0, reached - first + 1))
    return (f"$ /venv/bin/torchrun --nproc_per_node=2 /venv/bin/lerobot-train --steps={steps}\n"
            f"INFO 2026-11-26 {start} ot_train.py:272 {{'batch_size': 16,\n"
            f"INFO 2026-11-26 {start} ot_train.py:441 cfg.steps={steps} (30)\n"
            f"{bar}INFO 2026-11-26 {end} ot_train.py:641 step:{reached} smpl:1K loss:-1.0\n")


def test_training_runs_time_every_call_of_a_resumed_training():
    """A training stopped twice: three calls, each timed from its own lines and placed by its bar; the second was
    killed mid-bar, so the third call's command line is glued to its last redraw."""
    first = train_call(0, 12, end="12:05:30")
    killed = train_call(10, 13, start="13:00:00", end="13:01:00")
    killed = killed[:killed.rindex("INFO")]  # killed before its next INFO line: the log ends on the bar
    last = train_call(10, 30, start="23:59:00", end="00:09:00").replace("2026-11-26 00:09", "2026-11-27 00:09")
    text = first + killed + last
    for log in (text, compact_text(text)):
        assert training_runs(log) == [TrainingRun(330.0, 0, 12), TrainingRun(0.0, 10, 13), TrainingRun(600.0, 10, 30)]
    assert training_runs("") == [] and training_runs("no lerobot-train here\n") == []
