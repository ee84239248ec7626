#!/bin/bash
# After chain4 (D3's trainings and open-loop cells): the blind-replay line of the looking protocol
# (docs/research/looking.md: plan from official init state 49, states 0-3 of tasks 0, 2, 4, 6, 8, shifts 0-6 cm in a
# ring of 4 directions), two shifts at once (one core each).
cd /work/exp84b
while [ ! -f logs/chain4.done ]; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
o=results/libero_object_looking/blind_replay
B="predvla blind-replay --suites libero_object --tasks 0,2,4,6,8 --source-state 49 --states 0-3"
S="--object-shift-pattern ring --object-shift-directions 4"
run() { d=$1; shift; $B "$@" --out $o/shift$d > logs/br_looking_shift$d.log 2>&1; }
(run 0; run 2 --object-shift-cm 2 $S; run 4 --object-shift-cm 4 $S) &
(run 1 --object-shift-cm 1 $S; run 3 --object-shift-cm 3 $S; run 6 --object-shift-cm 6 $S) &
wait
date -u > logs/chain5.done
