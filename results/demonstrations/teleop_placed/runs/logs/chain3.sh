#!/bin/bash
cd /work/exp84
while kill -0 19751 2>/dev/null || kill -0 19752 2>/dev/null; do sleep 5; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84 MUJOCO_GL=egl OMP_NUM_THREADS=1
o=results/demonstrations/blind_replay
B="predvla blind-replay --suites libero_object --tasks 2,3,6"
$B --states 0-9 --object-shift-cm 4 --object-shift-pattern cross --out $o/E3_scripted > logs/br_E3_scripted.log 2>&1 &
$B --style teleop --diversity 1 --states 0-9 --object-shift-cm 4 --object-shift-pattern cross --out $o/E3_teleop > logs/br_E3_teleop.log 2>&1
wait
date -u > logs/chain3.done
