#!/bin/bash
# Usage: trace_cell.sh CELL TASK  -- the D2 cell's exact lerobot-eval arguments for TASK (from its run record) under
# `predvla trace`, from the worktree /work/exp_d2olt (main at 74f90b8, where the cell ran), one core.
set -e
cell=$1; task=$2
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
rec=results/demonstrations/teleop/runs/records/$cell/libero_object/seed0.json
mapfile -t args < <(python - "$rec" "$task" <<'P'
import json, sys
record, task = json.load(open(sys.argv[1])), sys.argv[2]
cmd = next(c for c in record["commands"]["eval"] if f"--env.task_ids=[{task}]" in c)
for a in cmd[1:]:
    if not a.startswith("--output_dir="):
        print(a)
P
)
out=results/demonstrations/teleop/trace/${cell}_task$task
mkdir -p $out
(git log --oneline -1; date -u; printf '%s\n' "${args[@]}") > $out/trace.start
predvla trace $out "${args[@]}" > $out/trace.log 2>&1
date -u >> $out/trace.start
