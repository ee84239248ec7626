"""What a user installs holds what a user runs: `pip install .` ships the package and its plugin name, not
`research/`, and `predvla --help` lists at most MAX_SUBCOMMANDS subcommands, each under one job."""

import argparse
import fnmatch
import tomllib
from pathlib import Path

from lerobot_predvla.cli.main import JOBS, build_parser

REPO = Path(__file__).resolve().parents[1]
MAX_SUBCOMMANDS = 14


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def test_the_wheel_ships_the_package_and_not_the_checkouts_trees():
    find = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    shipped = [name for name in ("lerobot_predvla", "lerobot_policy_predvla", "research", "benchmarks", "tests")
               if any(fnmatch.fnmatch(name, pattern) for pattern in find["include"])]
    assert shipped == ["lerobot_predvla", "lerobot_policy_predvla"]


def test_predvla_help_lists_few_subcommands_grouped_by_job():
    parser = build_parser()
    commands = _subcommands(parser)
    assert len(commands) <= MAX_SUBCOMMANDS, sorted(commands)
    assert list(JOBS) == ["data", "train and evaluate", "publish", "diagnose"]
    text = parser.format_help()
    headings = [text.index(f"\n{job}:\n") for job in JOBS]
    assert headings == sorted(headings), "the jobs in JOBS order"
    for job, start, end in zip(JOBS, headings, [*headings[1:], len(text)], strict=True):
        section = text[start:end]
        listed = [name for name in commands if f"\n  {name} " in section]
        assert len(listed) == len(JOBS[job]), f"{job}: {listed}"
    assert all(text.count(f"\n  {name} ") == 1 for name in commands), "each subcommand under exactly one job"


def test_the_demos_are_one_subcommand_with_a_setting():
    """`make demo` and `make synthetic-demo` run `predvla demo libero` and `predvla demo synthetic`."""
    parser = build_parser()
    assert set(_subcommands(_subcommands(parser)["demo"])) == {"libero", "synthetic", "robot"}
    makefile = (REPO / "Makefile").read_text()
    assert "predvla demo libero" in makefile and "predvla demo synthetic" in makefile
    args = parser.parse_args(["demo", "synthetic", "--steps", "3"])
    assert args.setting == "synthetic" and args.steps == 3 and callable(args.func)
