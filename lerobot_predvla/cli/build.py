"""`predvla build`: compile the C++ recurrence (error regression's loops, `recurrence_backend="auto"`) ahead of
the first rollout, once per Python and torch version (`make install` runs it).

Without a C++ compiler or ninja it says so and exits 0: "auto" then runs the Python loops (same results, slower).
A build that fails with a compiler present exits 1 with the compiler's message.
"""

import argparse
import time

from lerobot_predvla.policies.predvla import recurrence_cpp


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "build", help="compile the C++ error-regression loops once, ahead of the first rollout", description=__doc__
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    reason = recurrence_cpp.missing_toolchain()
    if reason is not None:
        print(f"predvla build: {reason}. recurrence_backend='auto' will run the Python loops (same results; "
              "error regression ~1.6x slower on CPU).")
        return 0
    start = time.perf_counter()
    try:
        module = recurrence_cpp.extension()
    except RuntimeError as error:
        print(f"predvla build: {error}")
        return 1
    print(f"predvla build: C++ recurrence ready in {recurrence_cpp.build_directory()} "
          f"({time.perf_counter() - start:.1f} s; tanh: {module.tanh_kernel()}).")
    return 0
