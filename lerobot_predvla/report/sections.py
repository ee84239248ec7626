"""The sections of a report beyond its tables of success: the stages' wall times and recorded commands, what a
fresh clone recomputes, the demonstrations' starts, the mechanism over training (`predvla inspect` beside the report)
and the baselines' learning rates chosen on held-out demonstrations."""

import json
import re
import sys
from pathlib import Path

import numpy as np

from lerobot_predvla.policies.predvla.configuration_predvla import MODULE_NAMES
from lerobot_predvla.report.formatting import MISSING, table
from lerobot_predvla.report.results import load_json
from lerobot_predvla.sims.libero.protocol import SUITE_LABELS
from lerobot_predvla.sweep.layout import DATA_DIR, TRAIN_DIR, TRAIN_DONE_FILE, run_log_path
from lerobot_predvla.sweep.logs import TrainingRun, training_runs
from lerobot_predvla.sweep.lr_selection import (
    CANDIDATE_PREFIX,
    LR_SWEEP_DIR,
    candidate_name,
    pending_selections,
)
from lerobot_predvla.utils.statistics import episode_totals

NOT_RUN = "not run yet"  # a learning-rate candidate of a sweep still running
# beside the report: `python -m lerobot_predvla.sims.libero.start_spread --demos`
START_SPREAD_FILE = "start_spread.json"
INSPECT_DIR = "inspect"  # beside the report: inspect/seed<N>/ from `predvla inspect <train dir> --every N`
CURVES_FIGURE = "training_curves.png"


# An absolute path's machine-specific head, whichever checkout recorded it: up to a virtual environment's bin/ or up
# to one of the repository's top-level folders (a word, or a flag's value after "=").
MACHINE_PREFIX = re.compile(r"(^|=)/[^\s=]*?/(?:\.venv/bin/|(?=(?:outputs|results|checkpoints|configs)/))")


def _relative(command: list[str]) -> str:
    """A recorded command as a reader runs it from the repository root (no machine-specific prefixes)."""
    prefixes = (f"{Path(sys.executable).parent}/", f"{Path.cwd()}/")
    words = []
    for word in command:
        for prefix in prefixes:
            word = word.replace(prefix, "")
        word = MACHINE_PREFIX.sub(r"\1", word)
        words.append(f"'{word}'" if "[" in word else word)
    return " ".join(words)


def _stage_commands(command: list[str] | list[list[str]]) -> str:
    """A data stage's command, or the commands of the processes that shared its work (run side by side)."""
    commands = command if command and isinstance(command[0], list) else [command]
    return " and ".join(f"`{_relative(c)}`" for c in commands)


def _training_minutes(record: dict, runs_dir: Path, read: dict[Path, list[TrainingRun]]) -> str:
    """A record's training wall time: from its training's log, over every `lerobot-train` call (the record's
    `train_wall_s` times the last call only), else the record's; the number of calls where there were several.
    `read`: the logs parsed so far (the records that evaluate one training share its log)."""
    trained = record.get("checkpoint_from") or record["config"]
    log = run_log_path(runs_dir, trained, record["suite"], record["seed"], "train")
    if log not in read:
        read[log] = training_runs(log.read_text(errors="replace")) if log.is_file() else []
    runs = read[log]
    wall = sum(r.wall_s for r in runs) if runs else record.get("train_wall_s")
    if not wall:
        return MISSING
    return f"{wall / 60:.0f}" + (f" ({len(runs)} calls)" if len(runs) > 1 else "")


def stages_section(records: list[dict], runs_dir: Path) -> list[str]:
    """Wall time of every recorded stage (data, training, evaluation) and the exact commands."""
    lines = []
    for path in sorted((Path(runs_dir) / DATA_DIR).glob("*.json")):
        stages = load_json(path)
        lines += [
            f"Data stages of {path.stem}:",
            "",
            table(
                ["stage", "wall time (min)", "command"],
                [[k, f"{v['wall_s'] / 60:.1f}", _stage_commands(v["command"])] for k, v in stages.items()],
            ),
            "",
        ]
    rows, commands, training_logs = [], [], {}
    for r in sorted(records, key=lambda r: (r["config"], r["suite"], int(r["seed"]))):
        _, episodes = episode_totals(r["tasks"].values())
        rows.append(
            [
                r["config"],
                r["suite"],
                str(r["seed"]),
                str(r.get("steps", MISSING)),
                _training_minutes(r, runs_dir, training_logs),
                f"{r['eval_wall_s'] / 60:.0f}" if r.get("eval_wall_s") else MISSING,
                str(episodes),
            ]
        )
        cmd = r.get("commands") or {}
        if cmd.get("train") and not r.get("checkpoint_from"):
            commands.append(f"- `{r['config']}` training: `{_relative(cmd['train'])}`")
        if cmd.get("eval"):
            commands.append(f"- `{r['config']}` evaluation, one task per call: `{_relative(cmd['eval'][0])}`")
    if not rows:
        return []
    lines += [
        table(["config", "suite", "seed", "training steps", "training (min)", "evaluation (min)", "episodes"], rows),
        "",
        "Training: the `lerobot-train` calls in its log together (a training resumed after a stop has "
        "several; from the timestamps of their lines, short by less than a logging interval each). "
        "Evaluation: its finished parts together (with several workers, more than the time that passed).",
    ]
    if commands:
        lines += ["", "Commands, as recorded (paths relative to the repository root):", "", *commands]
    return lines


def fresh_clone_section(runs_dir: Path) -> list[str]:
    """What a fresh clone of the repository recomputes and what it reads, stage by stage: the data stages (their
    outputs are never committed), and each finished training, whose model is read where its record names one outside
    the runs directory's `train/` (committed, e.g. by the sweep's `train.publish`) and is otherwise redone (its
    checkpoints stay on the machine that trained it), except a learning-rate candidate whose held-out result is
    committed: the sweep reads that result and never needs the candidate's model again."""
    runs_dir = Path(runs_dir).resolve()
    candidate_results = {
        (candidate_name(path.parent.parent.name, json.loads(path.read_text())["lr"]), path.parent.name): path
        for path in (runs_dir / LR_SWEEP_DIR).glob(f"*/*/{CANDIDATE_PREFIX}*.json")
    }
    rows = []
    for path in sorted((runs_dir / DATA_DIR).glob("*.json")):
        stages = load_json(path)
        minutes = sum(v["wall_s"] for v in stages.values()) / 60
        rows.append(
            [
                f"data of {path.stem} ({', '.join(stages)})",
                f"recomputed from the sweep file ({minutes:.0f} min as recorded); needed only to train",
            ]
        )
    for path in sorted((runs_dir / TRAIN_DIR).glob(f"*/*/seed*/{TRAIN_DONE_FILE}")):
        trained = load_json(path)
        checkpoint = (runs_dir / trained["checkpoint"]).resolve()
        config, suite, seed = path.parts[-4], path.parts[-3], path.parts[-2].removeprefix("seed")
        local = checkpoint.is_relative_to(runs_dir / TRAIN_DIR)
        result = candidate_results.get((config, suite))
        if result is not None:
            done = f"not needed: its held-out result is read from `{_relative([str(result)])}`"
        elif local:
            done = f"redone ({trained['steps']:,} steps): its checkpoint stays on the machine that trained it"
        else:
            done = f"read from `{_relative([str(checkpoint)])}`"
        rows.append([f"training {config} / {suite} / seed {seed}", done])
    if not rows:
        return []
    return [
        "",
        "## On a fresh clone",
        "",
        "Every stage is skipped when its output exists; run records, `eval_info.json` files and logs are "
        "committed, so a fresh clone runs only the missing runs, and these stages where a missing run needs them:",
        "",
        table(["stage", "on a fresh clone"], rows),
    ]


def starts_section(path: Path) -> list[str]:
    """The demonstrations' starts against the official init states (mean over tasks of `start_spread.json`)."""
    if not path.is_file():
        return []
    tasks = json.loads(path.read_text())["tasks"]

    def mean(kind: str, key: str) -> float:
        return float(
            np.mean(
                [t[kind][key] if key == "joint_std" else np.mean(list(t[kind][key].values())) for t in tasks.values()]
            )
        )

    gap_mm = max(
        1000 * float(np.abs(np.subtract(t["demonstrations"]["object_mean"][o], t["official"]["object_mean"][o])).max())
        for t in tasks.values()
        for o in t["official"]["object_mean"]
    )
    return [
        "",
        "## Demonstrations' starts",
        "",
        f"The demonstrations' first simulator states against the official init states, mean over {len(tasks)} "
        f"tasks (`{path.name}`); every object's mean position lies within {gap_mm:.1f} mm of the official one.",
        "",
        table(
            ["", "demonstrations", "official init states"],
            [
                [
                    "arm joints, std over starts (rad)",
                    f"{mean('demonstrations', 'joint_std'):.4f}",
                    f"{mean('official', 'joint_std'):.4f}",
                ],
                [
                    "objects, std of x, y over starts (mm)",
                    f"{1000 * mean('demonstrations', 'object_std'):.2f}",
                    f"{1000 * mean('official', 'object_std'):.2f}",
                ],
            ],
        ),
    ]


def mechanism_rows(history: list[dict]) -> list[list[str]]:
    """One row per inspected checkpoint of `predvla inspect`'s history."""
    rows = []
    for h in history:
        lang, removed, post = h["language"], h["proprio_error_per_dim"].get("removed"), h.get("posteriors")
        rows.append(
            [
                f"{h['step']:,}" if h.get("step") is not None else MISSING,
                f"{100 * lang['open_loop_picks_own_task']:.0f}",
                f"{lang['mean_language_swap_mse']:.3f} / {lang['mean_demo_gap']:.3f}",
                " / ".join(
                    f"{100 * removed[k]:.0f}" if k in removed else MISSING for k in ("proprio", "vision", "action")
                )
                if removed
                else MISSING,
                " / ".join(f"{post[m]['prior_gap']:.3f}" for m in MODULE_NAMES) if post else MISSING,
            ]
        )
    return rows


def mechanism_section(out: Path) -> list[str]:
    """Per training seed inspected beside the report (`inspect/seed<N>/inspect.json`): the mechanism's numbers per
    checkpoint and the figure over training."""
    found = sorted(
        (p for p in (out / INSPECT_DIR).glob("seed*/inspect.json") if p.parent.name[4:].isdigit()),
        key=lambda p: int(p.parent.name[4:]),
    )  # seed<N>/: one seed over training, not single checkpoints
    if not found:
        return []
    lines = [
        "",
        "## The mechanism over training",
        "",
        "`predvla inspect` on the training checkpoints, without the simulator: how often the exact open loop is "
        "closest to its own task's mean demonstration (%, chance: one task in the number of tasks); how far "
        "swapping the instruction moves the open-loop actions, against how far the tasks' mean demonstrations "
        "lie apart (action MSE); the open-loop error the training posteriors remove (%, proprioceptive / "
        "visual prediction, action against the demonstrated one); the training prior-posterior gap per "
        "module (" + " / ".join(MODULE_NAMES) + ").",
    ]
    for path in found:
        seed = path.parent.name
        lines += [
            "",
            f"### {seed}",
            "",
            table(
                ["step", "open loop picks own task (%)", "language swap / demo gap", "error removed (%)", "prior gap"],
                mechanism_rows(json.loads(path.read_text())["history"]),
            ),
        ]
        if (path.parent / CURVES_FIGURE).is_file():
            lines += ["", f"![{seed} over training]({INSPECT_DIR}/{seed}/{CURVES_FIGURE})"]
    return lines


def lr_selection_section(runs_dir: Path) -> list[str]:
    """The baselines' learning rates, chosen on held-out demonstrations (`RUNS_DIR/lr_sweep/<config>/<suite>.json`
    of `predvla sweep`); a sweep still running shows its finished candidates
    (`RUNS_DIR/lr_sweep/<config>/<suite>/lr<rate>.json`)."""
    selections = [json.loads(path.read_text()) for path in sorted((Path(runs_dir) / LR_SWEEP_DIR).glob("*/*.json"))]
    selections += pending_selections(runs_dir)
    if not selections:
        return []
    rates = sorted({rate for sel in selections for rate in sel["heldout_nll"]}, key=float)

    def nll(sel: dict, rate: str) -> str:
        if rate not in sel["heldout_nll"]:
            return NOT_RUN
        return MISSING if sel["heldout_nll"][rate] is None else f"{sel['heldout_nll'][rate]:.3f}"

    def pending(sel: dict) -> str:
        done = len(sel["heldout_nll"])
        return f"pending ({done} candidate{'s' * (done != 1)} done)"

    rows = [
        [
            sel["config"],
            SUITE_LABELS.get(sel["suite"], sel["suite"]),
            *[nll(sel, r) for r in rates],
            f"{sel['chosen_lr']:g}" if "chosen_lr" in sel else pending(sel),
            f"{sel['steps']:,}",
            str(sum(len(v) for v in sel["heldout_episodes"].values())) if "heldout_episodes" in sel else MISSING,
        ]
        for sel in selections
    ]
    return [
        "",
        "## Baselines' learning rates",
        "",
        "Each baseline's learning rate is the one of lowest action NLL on held-out demonstrations (LeRobot's "
        "`--dataset.eval_split`), never on the evaluation's init states; the candidates train on the other "
        f"demonstrations ({MISSING}: diverged; {NOT_RUN}: a candidate of a sweep still running).",
        "",
        table(
            [
                "config",
                "suite",
                *[f"NLL at lr {r}" for r in rates],
                "chosen",
                "candidate steps",
                "held-out demonstrations",
            ],
            rows,
        ),
    ]
