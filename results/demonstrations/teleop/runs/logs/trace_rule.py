"""The amendment's rule (docs/research/demonstrations.md, "Amendment, before any evaluation of the screen"): among
the PredVLA cells whose error-regression mode and exact open loop both ran on a set, the largest |successes
difference| (ties: the set with the lower blind-replay figure, then Table 2's mode); in it the task with the most
discordant pairs (ties: the lowest task id). Prints 'CELL TASK' and the candidates on stderr."""
import json, sys
from pathlib import Path

runs = Path("/work/exp_d2olt/results/demonstrations/teleop/runs")
blind = {"": 28 / 30, "_resets": 30 / 30, "_shifted": 4 / 30}  # teleop plan, per set


def successes(cell):
    out = {}
    for f in sorted((runs / "eval" / cell / "libero_object/seed0").glob("task*/eval_info.json")):
        for t in json.loads(f.read_text())["per_task"]:
            out[int(t["task_id"])] = list(t["metrics"]["successes"])
    return out


cands = []
for model in ("olt", "table2"):
    for mode_rank, mode in enumerate(("", "_carried")):
        for s in blind:
            er, ol = f"{model}{mode}{s}", f"{model}_open_loop{s}"
            if not ((runs / "records" / er).is_dir() and (runs / "records" / ol).is_dir()):
                continue
            a, b = successes(er), successes(ol)
            diff = abs(sum(map(sum, a.values())) - sum(map(sum, b.values())))
            disc = {t: sum(x != y for x, y in zip(a[t], b[t], strict=True)) for t in a}
            cands.append((-diff, blind[s], mode_rank, er, disc))
cands.sort(key=lambda c: c[:3])
for c in cands:
    print(c, file=sys.stderr)
best = cands[0]
task = min(best[4], key=lambda t: (-best[4][t], t))
print(best[3], task)
