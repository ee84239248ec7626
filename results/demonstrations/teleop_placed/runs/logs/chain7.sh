#!/bin/bash
# D3 screen, continued (commit 23acc29), replacing chain6's order after its carried E2p cells: the BC baselines on
# E2p first (the closed-loop reference on the set that tests the first target), then the carried cells on E3, then
# Table 2's error regression. One line per core; each waits for the chain6 cell it follows (pid given).
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
line() { after=$1; shift
  while kill -0 $after 2>/dev/null; do sleep 15; done
  for c in "$@"; do
    predvla sweep $S --runs-dir $R --configs $c --eval-workers 1 > logs/eval7_$c.log 2>&1
    echo "$(date -u) $c rc=$?" >> logs/chain7.progress
  done; }
line 9123 B1_placed_resets olt_carried_shifted olt_placed_resets olt_shifted &
line 9183 B2_placed_resets table2_carried_shifted B1_shifted B2_shifted table2_placed_resets table2_shifted &
wait
date -u > logs/chain7.done
