"""`predvla report`: paper-format tables, figures and a Markdown report from the records of `predvla sweep`; with
`--docs`, the headline results table of README.md and docs/results.md from the committed results/*/report.json and
the configs (no pinned device or machine paths) and model cards of the committed checkpoints."""

import argparse
import sys
from pathlib import Path

from lerobot_predvla.cli.arguments import int_list
from lerobot_predvla.report import REPORT_FILE, ReportError, write_report
from lerobot_predvla.report.headline import README, RESULTS_DOC, update_docs


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "report",
        help="tables (mean ± std across seeds, suite means, paired deltas, ladder) and figures from sweep runs; "
             "--docs: the README's and docs/results.md's headline table",
        description=__doc__,
    )
    parser.add_argument("runs_dir", type=Path, nargs="?",
                        help="The --runs-dir of `predvla sweep` (records/ and plan.json).")
    parser.add_argument("--out", type=Path, help="Report directory (report.md, report.json, PNGs).")
    parser.add_argument("--blind-replay", type=Path, nargs="+", default=[], metavar="DIR",
                        help="Reports of `predvla blind-replay`, one object shift each: one plan replayed blind as a "
                             "reference row and dashed line of the robustness table and figure.")
    parser.add_argument("--tasks-apart", type=int_list("--tasks-apart"), default=None, metavar="IDS",
                        help="Task ids (e.g. 2,3,6 or 0-4; the tasks a screen chose settings on): the paired "
                             "episodes are also counted on these tasks and on the other tasks apart.")
    parser.add_argument("--docs", action="store_true",
                        help=f"Rewrite the headline block of {README} and {RESULTS_DOC} from results/*/report.json "
                             "and the configs and model cards of every checkpoint under checkpoints/ (no RUNS_DIR).")
    parser.add_argument("--check", action="store_true",
                        help="With --docs: change nothing; exit 1 when a headline block or checkpoint file differs.")
    parser.add_argument("--root", type=Path, default=Path("."),
                        help="With --docs: the repository root (holding README.md, docs/ and results/).")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.docs == (args.runs_dir is not None) or (not args.docs and args.out is None):
        print("predvla report: error: give RUNS_DIR --out REPORT_DIR, or --docs.", file=sys.stderr)
        return 2
    try:
        if args.docs:
            return _docs(args)
        summary = write_report(args.runs_dir, args.out, args.blind_replay, args.tasks_apart)
    except ReportError as err:
        print(f"predvla report: error: {err}", file=sys.stderr)
        return 2
    print(f"predvla report: {len(summary['configs'])} configurations, {len(summary['missing_runs'])} missing runs, "
          f"figures {sorted(summary['figures'].values())}; see {args.out / REPORT_FILE}")
    return 0


def _docs(args: argparse.Namespace) -> int:
    changed = update_docs(args.root, check=args.check)
    if args.check:
        for path in changed:
            print(f"predvla report: {path}: differs from what the committed reports and checkpoints give; run "
                  "`predvla report --docs`.", file=sys.stderr)
        return 1 if changed else 0
    print(f"predvla report: {'rewrote ' + ', '.join(map(str, changed)) if changed else 'documents unchanged'}")
    return 0
