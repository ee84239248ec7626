#!/bin/bash
# Looking protocol's remaining cells (and issue 84's D2 trace first), two workers on two cores sharing this ordered
# list: `chain24.sh 1 &` and `chain24.sh 2 &`; a worker claims the next unclaimed cell (mkdir is atomic), one core,
# from the worktree at 0cad4ff. A cell starts only while it can end before the sitting does: error regression and
# the carried Adam until 15:38 UTC, BC until 15:48 UTC.
cd /work/exp_look
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_look MUJOCO_GL=egl OMP_NUM_THREADS=1
P=results/libero_object_looking/runs/logs/chains/chain24.progress
C=/work/notes/chain24.claims; mkdir -p $C
for c in d2_trace b2_pro_temp_x01 b2_pro_temp_y01 b2_pro_temp_x02 b2_pro_temp_y02 b2_pro_lan b2_plus_language_1 \
    carried_pro_temp_x01 carried_pro_temp_y01 carried_pro_swap carried_pro_with_yellow_book carried_pro_lan \
    carried_plus_language_1 er_pro_temp_x01 er_pro_temp_y01 er_pro_swap er_pro_with_yellow_book \
    carried_pro_temp_x02 carried_pro_temp_y02 er_pro_temp_x02 er_pro_temp_y02; do
  mkdir $C/$c 2>/dev/null || continue
  case $c in b[12]_*) last=1548 ;; *) last=1538 ;; esac
  if [ "$(date -u +%H%M)" -gt "$last" ]; then echo "$(date -u) w$1 skip $c (after $last)" >> $P; continue; fi
  if [ $c = d2_trace ]; then
    bash /work/exp_d2olt/results/demonstrations/teleop/runs/logs/trace_cell.sh olt_carried_resets 6
  else
    predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs $c \
      --eval-workers 1 > logs/eval_look_$c.log 2>&1
  fi
  echo "$(date -u) w$1 eval $c rc=$?" >> $P
done
