"""`predvla demo`: the plugin end to end, one demonstration per setting.

  predvla demo libero      the LIBERO simulator: demonstrations -> front end -> convert -> train -> eval (`make demo`)
  predvla demo synthetic   a generated dataset, no simulator: train, then replay (`make synthetic-demo`)
  predvla demo robot       a tiny SO-101 recording and a checkpoint trained on it, for the robot dry run

`predvla demo SETTING --help` lists each one's options.
"""

import argparse

from lerobot_predvla.cli import libero_demo, robot_example, synthetic


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("demo", help="the plugin end to end: libero (make demo), synthetic, robot",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    settings = parser.add_subparsers(dest="setting", required=True, metavar="SETTING")
    for module in (libero_demo, synthetic, robot_example):
        module.add_parser(settings)
