#!/bin/bash
# D2 fit_sensory_olt's remaining cells, after chain_d2_olt_cells.sh (whose cells took 7-13 min each at two workers,
# less than its guard assumed): a cell starts only until 12:30 UTC (about 13 min each), so that it ends before the
# sitting does; a cell already evaluated is skipped by the sweep itself.
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
P=results/demonstrations/teleop/runs/logs/chains/chain_d2_olt.progress
while pgrep -f "chains/chain_d2_olt_cells.sh" > /dev/null; do sleep 30; done
for c in olt olt_resets olt_carried olt_carried_resets; do
  if [ -e results/demonstrations/teleop/runs/records/$c ]; then continue; fi
  if [ "$(date -u +%H%M)" -gt 1230 ]; then echo "$(date -u) skip $c (after 1230)" >> $P; continue; fi
  predvla sweep configs/sweeps/libero_object_demos_teleop.yaml --runs-dir results/demonstrations/teleop/runs \
    --configs $c --eval-workers 2 > logs/d2_eval_$c.log 2>&1
  echo "$(date -u) eval $c rc=$?" >> $P
done
