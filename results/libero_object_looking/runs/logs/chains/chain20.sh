#!/bin/bash
# Looking protocol, the second core, from the worktree at 0cad4ff: error regression and the carried Adam unshifted
# (the references of the 1-6 cm cells), then BC-Transformer on LIBERO-PRO's and LIBERO-plus's variants. A cell starts
# only while it can end before the sitting does (LAST_START: error regression 08:55, BC 09:20 UTC).
cd /work/exp_look
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_look MUJOCO_GL=egl OMP_NUM_THREADS=1
for c in predvla_reading carried_shift0 b1_pro_lan b1_plus_language_1 b1_pro_with_yellow_book b1_pro_swap \
    b1_pro_temp_x01 b1_pro_temp_y01; do
  case $c in b1_*) last=0920 ;; *) last=0855 ;; esac
  if [ "$(date -u +%H%M)" -gt "$last" ]; then echo "$(date -u) skip $c (after $last)" >> results/libero_object_looking/runs/logs/chains/chain20.progress; continue; fi
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs $c \
    --eval-workers 1 > logs/eval_look_$c.log 2>&1
  echo "$(date -u) eval $c rc=$?" >> results/libero_object_looking/runs/logs/chains/chain20.progress
done
