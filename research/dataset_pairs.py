"""The demonstrations study's third paired comparison (docs/research/demonstrations.md, "Protocol"): the same policy
and mode trained on two datasets, episode by episode on the same starts.

Each argument `--runs LABEL=RUNS_DIR` is one dataset's sweep (`predvla sweep --runs-dir`); every evaluation cell
present in both (or the `--cells` named) is paired on the episodes both ran, when the two records start them alike
(`lerobot_predvla.report.paired.same_starts`: evaluation seed, reset mode, cap; and the same `--env.*` arguments:
shifts, placements, variants). The
exact two-sided sign test is on the pairs that succeed in only one. Command (from the repository root):

  python -m research.dataset_pairs --runs D2=results/demonstrations/teleop/runs \\
      --runs D3=results/demonstrations/teleop_placed/runs --out results/demonstrations/pairs_D3_D2

Writes OUT/pairs.json and OUT/pairs.md: per cell, the report's paired counts (`lerobot_predvla.report.paired`) of
the first dataset against the second (episodes paired, successes of each, only-first / only-second, the sign test's p).
"""

import argparse
import shlex
import sys
from pathlib import Path

from lerobot_predvla.report.formatting import table
from lerobot_predvla.report.paired import PAIR_COUNTS, add_pairs, same_starts, sum_counts, with_sign_test
from lerobot_predvla.report.results import ReportError, load_records, run_episodes
from lerobot_predvla.utils.io import atomic_write_json, atomic_write_text

COMMAND = "python -m research.dataset_pairs"


def env_args(record: dict) -> set[str]:
    """The `--env.*` arguments of a run's evaluation commands but the task ids (shifts, placements, variants)."""
    return {arg for command in record.get("commands", {}).get("eval", []) for arg in command
            if arg.startswith("--env.") and not arg.startswith("--env.task_ids")}


def alike(a: dict, b: dict) -> bool:
    """Whether episode i of a task starts from the same state in both records."""
    return same_starts(a, b) and env_args(a) == env_args(b)


def episode_pairs(mine: dict, theirs: dict, keys: set[tuple[str, int]]) -> dict:
    """PAIR_COUNTS and the sign test over the episode pairs `keys` of two runs (`run_episodes`), all tasks together."""
    tasks: dict[str, dict[str, int]] = {}
    add_pairs(tasks, mine, theirs, keys)
    return with_sign_test(sum_counts(tasks.values()) if tasks else dict.fromkeys(PAIR_COUNTS, 0))


def pair_cell(first: tuple[Path, dict], second: tuple[Path, dict]) -> dict | None:
    """Paired counts of one cell in two sweeps (runs dir, record); None when their starts differ."""
    (runs_a, rec_a), (runs_b, rec_b) = first, second
    if not alike(rec_a, rec_b):
        return None
    ep_a, ep_b = (run_episodes(runs, rec["config"], rec["suite"], int(rec["seed"]))
                  for runs, rec in ((runs_a, rec_a), (runs_b, rec_b)))
    return episode_pairs(ep_a, ep_b, ep_a.keys() & ep_b.keys())


def collect(runs: dict[str, Path], cells: list[str] | None) -> dict:
    (label_a, runs_a), (label_b, runs_b) = runs.items()
    records = [{(r["config"], r["suite"], int(r["seed"])): r for r in load_records(d)} for d in (runs_a, runs_b)]
    keys = sorted(records[0].keys() & records[1].keys())
    if cells is not None:
        missing = [c for c in cells if not any(k[0] == c for k in keys)]
        if missing:
            raise ValueError(f"--cells {','.join(missing)}: no run record in both {runs_a} and {runs_b}.")
        keys = [k for k in keys if k[0] in cells]
    pairs = {}
    for key in keys:
        paired = pair_cell((runs_a, records[0][key]), (runs_b, records[1][key]))
        pairs["/".join(map(str, key))] = paired if paired is not None else "starts differ"
    return {"datasets": [label_a, label_b], "runs": [str(runs_a), str(runs_b)], "cells": pairs}


def markdown(report: dict, command: str) -> str:
    a, b = report["datasets"]
    header = ["cell (config/suite/seed)", "episode pairs", f"successes {a} / {b}", f"only {a} / only {b}",
              "sign test p"]
    body = [[cell, "starts differ", "", "", ""] if isinstance(v, str) else
            [cell, str(v["pairs"]), f"{v['successes']} / {v['against_successes']}",
             f"{v['only']} / {v['only_against']}", f"{v['sign_test_p']:.2g}"] for cell, v in report["cells"].items()]
    return "\n".join([f"# The same cells trained on {a} and on {b}", "",
                      "Each episode against the same start (same task, evaluation seed, reset mode and shift); exact "
                      "two-sided sign test on the pairs that succeed in only one.", "", table(header, body), "",
                      "Reproduce:", "", "```bash", command, "```", ""])


def _runs(text: str) -> tuple[str, Path]:
    label, sep, path = text.partition("=")
    if not sep or not label or not path:
        raise argparse.ArgumentTypeError(f"--runs {text!r}: expected LABEL=RUNS_DIR, e.g. D2=results/.../runs")
    return label, Path(path)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=_runs, action="append", required=True,
                        help="LABEL=RUNS_DIR, twice: the two datasets' sweeps")
    parser.add_argument("--cells", type=lambda s: [c for c in s.split(",") if c], default=None,
                        help="comma-separated cell names (default: every cell both ran)")
    parser.add_argument("--out", type=Path, required=True)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser()
    args = parser.parse_args(argv)
    if len(args.runs) != 2 or args.runs[0][0] == args.runs[1][0]:
        parser.error("--runs: give exactly two, with different labels")
    for _, path in args.runs:
        if not (path / "records").is_dir():
            parser.error(f"--runs {path}: no records/ folder (a `predvla sweep --runs-dir`)")
    try:
        report = collect(dict(args.runs), args.cells)
    except (ValueError, ReportError) as err:
        print(f"{COMMAND}: error: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / "pairs.json", report)
    atomic_write_text(args.out / "pairs.md", markdown(report, f"{COMMAND} {shlex.join(argv)}"))
    print((args.out / "pairs.md").read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
