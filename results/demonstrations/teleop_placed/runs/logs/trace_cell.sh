#!/bin/bash
# Usage: trace_cell.sh CELL TASK  -- the D3 cell's exact lerobot-eval arguments for TASK (from its run record in
# /work/exp84b) under `predvla trace`, from the worktree /work/exp84c (main at a fixed commit), one core.
set -e
cell=$1; task=$2
cd /work/exp84c
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84c MUJOCO_GL=egl OMP_NUM_THREADS=1
rec=/work/exp84b/results/demonstrations/teleop_placed/runs/records/$cell/libero_object/seed0.json
mapfile -t args < <(python - "$rec" "$task" <<'P'
import json, sys
record, task = json.load(open(sys.argv[1])), sys.argv[2]
cmd = next(c for c in record["commands"]["eval"] if f"--env.task_ids=[{task}]" in c)
for a in cmd[1:]:
    if a.startswith("--output_dir="):
        continue
    print(a.replace("/work/exp84b/", "/work/exp84c/"))
P
)
out=results/demonstrations/teleop_placed/trace/${cell}_task$task
mkdir -p $out
(git log --oneline -1; date -u; printf '%s\n' "${args[@]}") > $out/trace.start
predvla trace $out "${args[@]}" > $out/trace.log 2>&1
date -u >> $out/trace.start
