"""Run logs without their progress bars' intermediate states.

`lerobot-train` and `lerobot-eval` draw tqdm bars into their logs: a bar redrawn after a carriage return on one
line (training) or on a fresh line after every step of a rollout, with cursor-up escapes for the nested bars
(evaluation). An evaluation of 500 episodes writes ~120,000 such lines. `compact_log` keeps each bar's last state
where a run of redraws ends and every other line as it is, so the messages, the step lines that
`lr_selection` and `kill_resume` read, and each bar's final count stay.

    python -m lerobot_predvla.sweep.logs results/*/runs/logs

`training_runs` reads a training's log back as the `lerobot-train` calls it holds: a training resumed after a stop
has one per call, and its wall time is theirs together.
"""

import re
import sys
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from lerobot_predvla.utils.io import atomic_write_bytes

# A tqdm bar and nothing else: "<desc>: 42%|████▏     | 21/50 [00:03<00:04, 6.7it/s, ...]".
_BAR = re.compile(r"(?P<desc>[^\r\n]*?): *\d+%\|[^|]*\| *\d+/\d+ \[[^\]]*\]")
_CURSOR = re.compile(r"\x1b\[[0-9]*[AK]")


def _is_bar(text: str) -> bool:
    return _BAR.fullmatch(text) is not None


def _last_segments(line: str) -> str:
    """A line redrawn after carriage returns: its bar states but the last dropped, any other text kept."""
    segments = line.split("\r")
    return "".join(s for s in segments[:-1] if s and not _is_bar(s)) + segments[-1]


def compact_text(text: str) -> str:
    """Each run of bar redraws (blank lines beside them dropped) becomes the last state of each bar in it."""
    out: list[str] = []
    run: dict[str, str] = {}  # the bars redrawn in the current run: desc -> last state
    blanks = 0  # blank lines waiting: dropped beside a bar, kept between other lines
    body, newline = (text[:-1], "\n") if text.endswith("\n") else (text, "")
    for raw in body.split("\n"):
        line = _CURSOR.sub("", _last_segments(raw))
        match = _BAR.fullmatch(line)
        if match:
            run.pop(match["desc"], None)  # re-inserted last: bars in the order of their last redraw
            run[match["desc"]] = line
            blanks = 0
        elif not line.strip():
            blanks += 1
        else:
            out.extend(run.values())
            out.extend([""] * (0 if run else blanks))
            run.clear()
            blanks = 0
            out.append(line)
    out.extend(run.values())
    out.extend([""] * (0 if run else blanks))
    return "\n".join(out) + newline


def compact_log(path: Path) -> int:
    """Rewrite `path` compacted (atomically); returns the bytes saved."""
    data = path.read_bytes()
    compacted = compact_text(data.decode("utf-8", errors="surrogateescape")).encode("utf-8", errors="surrogateescape")
    if compacted != data:
        atomic_write_bytes(path, compacted)
    return len(data) - len(compacted)


# What `training_runs` reads: the command line the sweep writes before each call ("$ .../torchrun ..."), the
# timestamp of each of lerobot-train's INFO lines, its total step count, and its progress bar, whose total is the
# steps left when the call started (a resumed call counts from its checkpoint).
_TRAIN_EVENT = re.compile(
    r"(?P<command>\$ \S*(?:torchrun|lerobot-train)\b)"
    r"|INFO (?P<stamp>\d{4}-\d\d-\d\d \d\d:\d\d:\d\d) "
    r"|cfg\.steps=(?P<steps>\d+)"
    r"|Training: *\d+%\|[^|]*\| *(?P<done>\d+)/(?P<left>\d+) \["
)


@dataclass(frozen=True)
class TrainingRun:
    """One `lerobot-train` call in a training's log."""

    wall_s: float  # its first to its last timestamped line: short of the true time by less than a logging interval
    first_step: int | None  # the step it started from (0, or the checkpoint it resumed); None: no progress bar
    last_step: int | None  # the last step its progress bar reached


def training_runs(text: str) -> list[TrainingRun]:
    """The `lerobot-train` calls of a training log, in order (lines before the first command line open one)."""
    runs: list[dict] = []
    for match in _TRAIN_EVENT.finditer(text):
        if match["command"] or not runs:
            runs.append({"stamps": [], "steps": None, "bar": None})
        run = runs[-1]
        if match["stamp"]:
            run["stamps"].append(datetime.fromisoformat(match["stamp"]))
        elif match["steps"]:
            run["steps"] = int(match["steps"])
        elif match["done"]:
            run["bar"] = int(match["done"]), int(match["left"])
    out = []
    for run in runs:
        stamps, first = run["stamps"], None
        if run["bar"] is not None and run["steps"] is not None:
            first = run["steps"] - run["bar"][1]
        out.append(TrainingRun(wall_s=(max(stamps) - min(stamps)).total_seconds() if stamps else 0.0,
                               first_step=first, last_step=None if first is None else first + run["bar"][0]))
    return out


def main(argv: list[str] | None = None) -> int:
    paths = [Path(p) for p in (sys.argv[1:] if argv is None else argv)]
    if not paths:
        print("usage: python -m lerobot_predvla.sweep.logs LOG_OR_DIR [...]", file=sys.stderr)
        return 2
    missing = [p for p in paths if not p.exists()]
    if missing:
        print(f"{missing[0]}: no such file or directory", file=sys.stderr)
        return 2
    logs = [log for p in paths for log in (sorted(p.rglob("*.log")) if p.is_dir() else [p])]
    saved = sum(compact_log(log) for log in logs)
    print(f"compacted {len(logs)} logs: {saved / 1e6:.1f} MB fewer")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
