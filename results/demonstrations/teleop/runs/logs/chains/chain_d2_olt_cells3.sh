#!/bin/bash
# D2 fit_sensory_olt's last cell, the carried Adam on E2, from the worktree at 74f90b8 (two task parts at once).
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
P=results/demonstrations/teleop/runs/logs/chains/chain_d2_olt.progress
predvla sweep configs/sweeps/libero_object_demos_teleop.yaml --runs-dir results/demonstrations/teleop/runs \
  --configs olt_carried_resets --eval-workers 2 > logs/d2_eval_olt_carried_resets.log 2>&1
echo "$(date -u) eval olt_carried_resets rc=$?" >> $P
