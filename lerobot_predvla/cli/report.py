"""`predvla report`: paper-format tables, figures and a Markdown report from the records of `predvla sweep`."""

import argparse
import sys
from pathlib import Path

from lerobot_predvla.experiments.report import REPORT_FILE, ReportError, write_report


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "report",
        help="Tables (mean ± std across seeds, suite means, paired deltas, ladder) and figures from sweep runs.",
        description=__doc__,
    )
    parser.add_argument("runs_dir", type=Path, help="The --runs-dir of `predvla sweep` (records/ and plan.json).")
    parser.add_argument("--out", type=Path, required=True, help="Report directory (report.md, report.json, PNGs).")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        summary = write_report(args.runs_dir, args.out)
    except ReportError as err:
        print(f"predvla report: error: {err}", file=sys.stderr)
        return 2
    print(f"predvla report: {len(summary['configs'])} configurations, {len(summary['missing_runs'])} missing runs, "
          f"figures {sorted(summary['figures'].values())}; see {args.out / REPORT_FILE}")
    return 0
