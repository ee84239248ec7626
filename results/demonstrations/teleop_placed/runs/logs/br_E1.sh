#!/bin/bash
# E1's blind-replay figures (official init states 1-9 of tasks 2, 3, 6; both styles), at the lowest priority beside
# the D3 trainings, one process.
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
o=results/demonstrations/blind_replay
B="predvla blind-replay --suites libero_object --tasks 2,3,6"
nice -n 19 $B --states 1-9 --out $o/E1_scripted > logs/br_E1_scripted.log 2>&1
nice -n 19 $B --style teleop --diversity 1 --states 1-9 --out $o/E1_teleop > logs/br_E1_teleop.log 2>&1
date -u > logs/br_E1.done
