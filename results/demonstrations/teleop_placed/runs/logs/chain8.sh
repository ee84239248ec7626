#!/bin/bash
# After chain7's first line (its last cell: olt_shifted), on the core it frees: the blind-replay line of the looking
# protocol (docs/research/looking.md: plan from official init state 49, states 0-3 of tasks 0, 2, 4, 6, 8, shifts
# 0-6 cm in a ring of 4 directions), one shift after another (resumable per task).
cd /work/exp84b
while ! grep -q " olt_shifted rc" logs/chain7.progress 2>/dev/null; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
o=results/libero_object_looking/blind_replay
B="predvla blind-replay --suites libero_object --tasks 0,2,4,6,8 --source-state 49 --states 0-3"
S="--object-shift-pattern ring --object-shift-directions 4"
run() { d=$1; shift; $B "$@" --out $o/shift$d > logs/br_looking_shift$d.log 2>&1; echo "$(date -u) shift$d" >> logs/chain8.progress; }
run 0; run 4 --object-shift-cm 4 $S; run 2 --object-shift-cm 2 $S; run 1 --object-shift-cm 1 $S; run 3 --object-shift-cm 3 $S
run 6 --object-shift-cm 6 $S
date -u > logs/chain8.done
