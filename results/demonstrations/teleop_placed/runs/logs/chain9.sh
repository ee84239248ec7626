#!/bin/bash
# D3 screen, continued (commit 23acc29): the rest of Table 2 literal's Table 2 ER on E3 (tasks 3 and 6), then the
# official-state cells (E1: each PredVLA in three modes, B1, B2), then the randomised-reset cells (E2) as time allows.
# One line per core, each cell one sweep call (resumable per task).
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
line() { for c in "$@"; do
    predvla sweep $S --runs-dir $R --configs $c --eval-workers 1 > logs/eval9_$c.log 2>&1
    echo "$(date -u) $c rc=$?" >> logs/chain9.progress
  done; }
line table2_shifted olt_open_loop olt olt_carried B1 B1_resets olt_open_loop_resets &
line table2_open_loop table2 table2_carried B2 B2_resets table2_open_loop_resets &
wait
date -u > logs/chain9.done
