#!/bin/bash
# D2 fit_sensory_olt's cells from the worktree at 74f90b8, after chain_d2_olt_train.sh, two task parts at once: the
# object shifted 4 cm first (the decisive set), then the exact open loop on the official states and the resets. A cell
# starts only while it can end before the sitting does (measured on D2's table2 cells: open loop 6-13 min, error
# regression and the carried Adam 23-26 min at two workers).
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
P=results/demonstrations/teleop/runs/logs/chains/chain_d2_olt.progress
while pgrep -f "chains/chain_d2_olt_train.sh" > /dev/null; do sleep 30; done
for c in olt_open_loop_shifted olt_shifted olt_carried_shifted olt_open_loop olt_open_loop_resets olt olt_resets \
    olt_carried olt_carried_resets; do
  case $c in olt_open_loop*) last=1228 ;; *) last=1215 ;; esac
  if [ "$(date -u +%H%M)" -gt "$last" ]; then echo "$(date -u) skip $c (after $last)" >> $P; continue; fi
  predvla sweep configs/sweeps/libero_object_demos_teleop.yaml --runs-dir results/demonstrations/teleop/runs \
    --configs $c --eval-workers 2 > logs/d2_eval_$c.log 2>&1
  echo "$(date -u) eval $c rc=$?" >> $P
done
