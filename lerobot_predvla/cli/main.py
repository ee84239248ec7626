"""The `predvla` console command: one entry point, one module per subcommand.

Each subcommand module exposes `add_parser(subparsers)` which registers its parser and sets
`func` to a callable taking the parsed namespace and returning an exit code.
"""

import argparse
import importlib
import sys

# Subcommand modules, in the order `predvla --help` lists them.
SUBCOMMAND_MODULES = [
    "lerobot_predvla.cli.libero_demo",
    "lerobot_predvla.cli.synthetic",
    "lerobot_predvla.cli.demos",
    "lerobot_predvla.cli.blind_replay",
    "lerobot_predvla.cli.demo_styles",
    "lerobot_predvla.cli.fit_frontend",
    "lerobot_predvla.cli.convert",
    "lerobot_predvla.cli.features_only",
    "lerobot_predvla.cli.inspect",
    "lerobot_predvla.cli.mechanism",
    "lerobot_predvla.cli.trace",
    "lerobot_predvla.cli.er_correction",
    "lerobot_predvla.cli.er_timing",
    "lerobot_predvla.cli.divergence",
    "lerobot_predvla.cli.oracle_probe",
    "lerobot_predvla.cli.sweep",
    "lerobot_predvla.cli.report",
    "lerobot_predvla.cli.push",
    "lerobot_predvla.cli.bench",
    "lerobot_predvla.cli.build",
    "lerobot_predvla.cli.robot_example",
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
