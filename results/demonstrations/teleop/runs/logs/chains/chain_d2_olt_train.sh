#!/bin/bash
# D2 fit_sensory_olt's training (screening scale, 10,000 steps, two DDP processes) from the worktree at 74f90b8 on the
# dataset remade bit for bit by chain_d2_olt.sh; the sweep publishes the model to checkpoints/demonstrations/teleop/.
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
P=results/demonstrations/teleop/runs/logs/chains/chain_d2_olt.progress
echo "$(date -u) start train olt" >> $P
predvla sweep configs/sweeps/libero_object_demos_teleop.yaml --runs-dir results/demonstrations/teleop/runs \
  --configs olt --train-only > logs/d2_olt_train.log 2>&1
echo "$(date -u) train olt rc=$?" >> $P
