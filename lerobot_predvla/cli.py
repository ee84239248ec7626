"""The `predvla` console command: one entry point, one module per subcommand.

Each subcommand module exposes `add_parser(subparsers)` which registers its parser and sets
`func` to a callable taking the parsed namespace and returning an exit code.
"""

import argparse
import importlib
import sys

# Subcommand modules, in the order `predvla --help` lists them.
SUBCOMMAND_MODULES = [
    "lerobot_predvla.commands.libero_demo",
    "lerobot_predvla.commands.synthetic",
    "lerobot_predvla.commands.demos",
    "lerobot_predvla.commands.fit_frontend",
    "lerobot_predvla.commands.convert",
    "lerobot_predvla.commands.inspect",
    "lerobot_predvla.commands.sweep",
    "lerobot_predvla.commands.report",
    "lerobot_predvla.commands.push",
    "lerobot_predvla.commands.bench",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="predvla", description=__doc__.splitlines()[0])
    subparsers = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
