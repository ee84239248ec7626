#!/bin/bash
# D3 screen, continued: trains fit_sensory_olt then B2 (no evaluation), then the exact-open-loop cells of the two
# PredVLA models on E2p (placed resets) and E3 (object shifted 4 cm), two sweep calls at once (one core each).
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
for c in olt B2; do
  (git log --oneline -1; date -u) > logs/train_$c.start
  predvla sweep $S --runs-dir $R --configs $c --train-only > logs/train_$c.log 2>&1
  date -u >> logs/train_$c.start
done
predvla sweep $S --runs-dir $R --configs olt_open_loop_placed_resets,olt_open_loop_shifted --eval-workers 1 > logs/eval_olt_ol.log 2>&1 &
predvla sweep $S --runs-dir $R --configs table2_open_loop_placed_resets,table2_open_loop_shifted --eval-workers 1 > logs/eval_table2_ol.log 2>&1
wait
date -u > logs/chain4.done
