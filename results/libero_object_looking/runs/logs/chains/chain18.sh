#!/bin/bash
# Looking protocol, one core, from the worktree at 8c89569: BC-RNN on the unshifted starts (its 4 cm cell's reference).
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs B2 \
  --eval-workers 1 > logs/eval_look_B2.log 2>&1
echo "$(date -u) eval B2 rc=$?" >> results/libero_object_looking/runs/logs/chains/chain18.progress
