#!/bin/bash
# Looking protocol, one core, from the worktree at 0cad4ff, after chain21.sh on its core. A cell starts only while it
# can end before the sitting does: error regression and the carried Adam until 09:12 UTC, BC until 09:22 UTC.
cd /work/exp_look
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_look MUJOCO_GL=egl OMP_NUM_THREADS=1
P=results/libero_object_looking/runs/logs/chains/chain23.progress
while pgrep -f "chains/chain21.sh" > /dev/null; do sleep 30; done
for c in er_pro_lan b2_pro_with_yellow_book b2_pro_swap b2_pro_temp_x01 b2_pro_temp_y01 b2_pro_temp_y02; do
  case $c in b[12]_*) last=0922 ;; *) last=0912 ;; esac
  if [ "$(date -u +%H%M)" -gt "$last" ]; then echo "$(date -u) skip $c (after $last)" >> $P; continue; fi
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs $c \
    --eval-workers 1 > logs/eval_look_$c.log 2>&1
  echo "$(date -u) eval $c rc=$?" >> $P
done
