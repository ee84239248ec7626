#!/bin/bash
# D3 screen, continued (from committed models, commit 23acc29): E3's open-loop cells finish (task 6), then the
# error-regression cells, carried Adam first (cheaper), one line per PredVLA model, one core each.
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
line() { m=$1
  for c in ${m}_open_loop_shifted ${m}_carried_placed_resets ${m}_placed_resets ${m}_carried_shifted ${m}_shifted; do
    predvla sweep $S --runs-dir $R --configs $c --eval-workers 1 > logs/eval6_$c.log 2>&1
    echo "$(date -u) $c rc=$?" >> logs/chain6.progress
  done; }
line olt &
line table2 &
wait
date -u > logs/chain6.done
