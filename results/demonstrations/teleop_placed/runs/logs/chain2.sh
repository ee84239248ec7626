#!/bin/bash
# Continues the D3 chain: waits for table2's training, trains B1 (no evaluation), runs main's whole test suite, then the
# blind-replay figures of the evaluation sets for both styles (tasks 2, 3, 6), two at a time, E2p and E3 first.
cd /work/exp84
while kill -0 14306 2>/dev/null; do sleep 15; done
date -u >> logs/train_table2.start
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
(git log --oneline -1; date -u) > logs/train_B1.start
predvla sweep $S --runs-dir $R --configs B1 --train-only > logs/train_B1.log 2>&1
date -u >> logs/train_B1.start
(cd /work/main && PYTHONPATH= OMP_NUM_THREADS=1 timeout 1500 python -m pytest -q -n 2 --dist loadscope tests > /work/exp84/logs/main_tests.log 2>&1; echo "rc=$?" >> /work/exp84/logs/main_tests.log)
o=results/demonstrations/blind_replay
B="predvla blind-replay --suites libero_object --tasks 2,3,6"
T="--style teleop --diversity 1"
run() { local name=$1; shift; $B "$@" --out $o/$name > logs/br_$name.log 2>&1; }
run E2p_scripted --resets-seed 3000 --episodes 10 --placement-spread-cm 3 &
run E2p_teleop $T --resets-seed 3000 --episodes 10 --placement-spread-cm 3; wait
run E3_scripted --states 0-9 --object-shift-cm 4 --object-shift-pattern cross &
run E3_teleop $T --states 0-9 --object-shift-cm 4 --object-shift-pattern cross; wait
run E2_scripted --resets-seed 3000 --episodes 10 &
run E2_teleop $T --resets-seed 3000 --episodes 10; wait
run E1_scripted --states 1-9 &
run E1_teleop $T --states 1-9; wait
date -u > logs/chain.done
