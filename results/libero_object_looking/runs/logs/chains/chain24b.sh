#!/bin/bash
# Replaces chain24.sh's worker 1 (killed while its cell b2_pro_temp_y01, pid $1, ran on): waits for that cell, then
# traces D2's exact open loop on the traced cell's task and starts (issue 84's item 4, for the gripper timing), then
# goes on with chain24.sh's list as its worker 1, the same claims and deadlines.
cd /work/exp_look
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_look MUJOCO_GL=egl OMP_NUM_THREADS=1
P=results/libero_object_looking/runs/logs/chains/chain24.progress
C=/work/notes/chain24.claims
while kill -0 $1 2>/dev/null; do sleep 10; done
echo "$(date -u) w1 eval b2_pro_temp_y01 ended (worker 1 now chain24b.sh)" >> $P
bash /work/exp_d2olt/results/demonstrations/teleop/runs/logs/trace_cell.sh olt_open_loop_resets 6
echo "$(date -u) w1 trace olt_open_loop_resets task 6 rc=$?" >> $P
for c in b2_pro_temp_y02 b2_pro_lan b2_plus_language_1 \
    carried_pro_temp_x01 carried_pro_temp_y01 carried_pro_swap carried_pro_with_yellow_book carried_pro_lan \
    carried_plus_language_1 er_pro_temp_x01 er_pro_temp_y01 er_pro_swap er_pro_with_yellow_book \
    carried_pro_temp_x02 carried_pro_temp_y02 er_pro_temp_x02 er_pro_temp_y02; do
  mkdir $C/$c 2>/dev/null || continue
  case $c in b[12]_*) last=1548 ;; *) last=1538 ;; esac
  if [ "$(date -u +%H%M)" -gt "$last" ]; then echo "$(date -u) w1 skip $c (after $last)" >> $P; continue; fi
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir results/libero_object_looking/runs --configs $c \
    --eval-workers 1 > logs/eval_look_$c.log 2>&1
  echo "$(date -u) w1 eval $c rc=$?" >> $P
done
