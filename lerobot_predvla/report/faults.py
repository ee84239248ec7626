"""A table of fault-injection evaluations: `python -m lerobot_predvla.report.faults EVAL_INFO.json ...`.

Each file is the `eval_info.json` of a `lerobot-eval --env.type=predvla_libero --env.fault_rate=x` run; its
`predvla_faults` section (written by `lerobot_predvla.sims.libero`) holds the injected faults, the observation steps
the policy masked out of the free energy and the count of non-finite actions. Prints one Markdown row per file,
clean runs (no injection) first.
"""

import argparse
import json
import sys
from pathlib import Path

from lerobot_predvla.sweep.eval_info import EvalInfoError, parse_eval_info

VISION, PROPRIO = "observation.vision_features", "observation.state"
HEADER = ("| fault rate x | mode | success | non-finite actions | replaced actions | faulted episodes "
          "| injected vision / proprio | masked vision / proprio |\n|---|---|---|---|---|---|---|---|")


def fault_row(path: Path) -> tuple[float, str, str]:
    """(rate, mode, Markdown row) of one fault-injection eval_info.json."""
    tasks = parse_eval_info(path)
    successes, episodes = (sum(t[k] for t in tasks.values()) for k in ("successes", "episodes"))
    try:
        faults = json.loads(Path(path).read_text())["predvla_faults"]
        policy, injected = faults["policy"], faults.get("injected", {})
        rate, mode = float(injected.get("rate", 0.0)), str(injected.get("mode", "-"))
        row = (f"| {rate:g} | {mode} | {successes}/{episodes} | {faults['nonfinite_actions']} | "
               f"{policy['fallback_actions']} | {len(faults['faulted_episodes'])} | "
               f"{injected.get('vision', 0)} / {injected.get('proprio', 0)} | {policy[VISION]} / {policy[PROPRIO]} |")
    except (KeyError, TypeError, ValueError) as err:
        raise EvalInfoError(f"{path}: no `predvla_faults` section of a predvla_libero run ({err}).") from err
    return rate, mode, row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("eval_info", type=Path, nargs="+", help="eval_info.json files of fault-injection runs")
    args = parser.parse_args(argv)
    try:
        rows = sorted(fault_row(p) for p in args.eval_info)
    except EvalInfoError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(HEADER)
    for _, _, row in rows:
        print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
