"""The `predvla` console command: one entry point, one module per subcommand.

Each subcommand module exposes `add_parser(subparsers)` which registers its parser and sets
`func` to a callable taking the parsed namespace and returning an exit code. `predvla --help` lists the
subcommands by job (`JOBS`). The research diagnostics behind docs/research/ are not subcommands: they run from a
checkout as `python -m research.<name>`.
"""

import argparse
import importlib
import sys

# Subcommand modules by job, in the order `predvla --help` lists them.
JOBS = {
    "data": ["demos", "blind_replay", "fit_frontend", "convert", "features_only"],
    "train and evaluate": ["demo", "sweep", "build"],
    "publish": ["report", "push"],
    "diagnose": ["inspect", "trace", "bench"],
}
SUBCOMMAND_MODULES = [f"lerobot_predvla.cli.{name}" for names in JOBS.values() for name in names]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="predvla", description=__doc__.splitlines()[0],
                                     usage="predvla [-h] COMMAND ...")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", help=argparse.SUPPRESS,
                                       prog="predvla")
    listed = 0
    for job, names in JOBS.items():
        for name in names:
            importlib.import_module(f"lerobot_predvla.cli.{name}").add_parser(subparsers)
        # argparse lists a subparsers action's commands in one block; these lines move the commands just
        # registered into a help section of their own job.
        group = parser.add_argument_group(job)
        group._group_actions.extend(subparsers._choices_actions[listed:])
        listed = len(subparsers._choices_actions)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
