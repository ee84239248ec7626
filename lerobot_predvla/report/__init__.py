"""Paper-format tables and figures from the run records of `predvla sweep`.

Inputs: `RUNS_DIR/records/**/*.json` (one per configuration, suite and seed) and, when present,
`RUNS_DIR/plan.json` (every planned run and each configuration's description), which lets the report mark runs
that are missing. Outputs in REPORT_DIR: `report.md` (Markdown tables and figures, readable on GitHub),
`report.json` (the aggregates, read by `predvla push --results`) and the PNG figures.

Success rates are percentages per (configuration, suite, seed): successes / episodes over all tasks. Tables
show mean +/- sample standard deviation across seeds; 3-suite (spatial, goal, object) and 4-suite means are
means of the suite means and need every suite. Paired differences use the seeds both configurations have.

A configuration with `compare_to` (e.g. exact open loop against error regression) is also compared episode by
episode, from the runs' `eval_info.json` files: both runs of a seed start from the same init states when they share
the evaluation seed, reset mode and protocol, so each episode is a pair. The report counts the pairs that succeed
in only one of the two and gives the exact two-sided sign test on them. Two runs that load one checkpoint path
pair only when they evaluated the same weights (`same_model`).

Configurations that name another in `pool_with` (further training seeds of the same model and evaluation) also
get one row over the union of their seeds, and their paired episodes one sign test over all the seeds' pairs; a
configuration's `pool_sets` (the same comparison on other evaluation sets) gets one sign test over all the sets' pairs.

Modules by job: `results` (loading records, plans, episodes and `report.json`), `summary` (the statistics across
seeds), `paired` (paired episodes), `tables`, `figures`, `sections` (stages, fresh clone, starts, mechanism,
learning rates) and `writer` (`write_report`); success arithmetic is `lerobot_predvla.utils.statistics`'s,
Markdown tables and number formats `lerobot_predvla.report.formatting`'s.
"""

from lerobot_predvla.report.figures import FIGURES
from lerobot_predvla.report.formatting import MISSING
from lerobot_predvla.report.paired import paired_task_rates, same_starts
from lerobot_predvla.report.results import SUMMARY_FILE, ReportError, load_summary, run_episodes
from lerobot_predvla.report.sections import fresh_clone_section, stages_section
from lerobot_predvla.report.writer import REPORT_FILE, write_report
from lerobot_predvla.utils.statistics import sign_test

__all__ = [
    "FIGURES",
    "MISSING",
    "REPORT_FILE",
    "SUMMARY_FILE",
    "ReportError",
    "fresh_clone_section",
    "load_summary",
    "paired_task_rates",
    "run_episodes",
    "same_starts",
    "sign_test",
    "stages_section",
    "write_report",
]
