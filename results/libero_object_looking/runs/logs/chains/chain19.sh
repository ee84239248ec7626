#!/bin/bash
# Looking protocol, one core, from the worktree at 0cad4ff: error regression and the carried Adam at 6 cm (where the
# exact open loop fails every episode, so error regression can only win), then BC-RNN at 2 and 3 cm, then 1 cm.
cd /work/exp_look
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_look MUJOCO_GL=egl OMP_NUM_THREADS=1
for c in er_shift6 carried_shift6 b2_shift2 b2_shift3 er_shift1 carried_shift1 b2_shift1 b2_shift6; do
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs $c \
    --eval-workers 1 > logs/eval_look_$c.log 2>&1
  echo "$(date -u) eval $c rc=$?" >> results/libero_object_looking/runs/logs/chains/chain19.progress
done
