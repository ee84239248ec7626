"""`lerobot-train` with every loop iteration timed, for `benchmarks.profile_lerobot_train`.

Runs LeRobot's own `lerobot.scripts.lerobot_train.main` (plugins registered as the console script does) with its
module-level `update_policy` wrapped to record `time.perf_counter()` at each call: consecutive differences are the
wall time of whole training iterations (data, preprocessor, update, logging, checkpointing). Each process writes
its times to `$PREDVLA_TIMES_OUT.rank<RANK>.json` at exit. `$PREDVLA_PATCHES` (comma-separated) switches off one of
PredVLA's exact shortcuts for a comparison arm:

- `untrimmed`: run the recurrence over the batch's padding (`modeling_predvla.trim_padding` made the identity);
- `unshared`: the action term's chain rolled out a second time (`predictive_model.SHARED_ACTING_CHAIN` off).

    torchrun --nproc_per_node=2 -m benchmarks.lerobot_train_timed --policy.type=predvla ...
"""

import atexit
import json
import os
import time

from lerobot.scripts import lerobot_train

from lerobot_predvla.policies.predvla import modeling_predvla

PATCHES = ("untrimmed", "unshared")


def apply_patches(names: list[str]) -> None:
    unknown = sorted(set(names) - set(PATCHES))
    if unknown:
        raise SystemExit(f"$PREDVLA_PATCHES: unknown {unknown}; expected some of {PATCHES}.")
    if "untrimmed" in names:
        modeling_predvla.trim_padding = lambda seq, c_q: (seq, c_q)
    if "unshared" in names:
        modeling_predvla.SHARED_ACTING_CHAIN = False


def main() -> None:
    apply_patches([n for n in os.environ.get("PREDVLA_PATCHES", "").split(",") if n])
    times: list[float] = []
    update_policy = lerobot_train.update_policy

    def timed_update_policy(*args, **kwargs):
        times.append(time.perf_counter())
        return update_policy(*args, **kwargs)

    lerobot_train.update_policy = timed_update_policy
    out = os.environ.get("PREDVLA_TIMES_OUT")
    if out:
        rank = os.environ.get("RANK", "0")
        atexit.register(lambda: open(f"{out}.rank{rank}.json", "w").write(json.dumps(times)))
    lerobot_train.main()


if __name__ == "__main__":
    main()
