#!/bin/bash
# D3 screen, this sitting: waits for the data stage, then trains table2 and B1 (no evaluation), then the blind-replay
# figures of the four evaluation sets for both styles (tasks 2, 3, 6), two at a time.
cd /work/exp84
while pgrep -f "libero_object_demos_teleop_placed.yaml --runs-dir results/demonstrations/teleop_placed/runs --data-only" >/dev/null; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
for c in table2 B1; do
  (git log --oneline -1; date -u) > logs/train_$c.start
  predvla sweep $S --runs-dir $R --configs $c --train-only > logs/train_$c.log 2>&1
  date -u >> logs/train_$c.start
done
o=results/demonstrations/blind_replay
B="predvla blind-replay --suites libero_object --tasks 2,3,6"
T="--style teleop --diversity 1"
run() { $B "$@" > logs/br_$(echo "$@" | tr -c 'a-zA-Z0-9' '_' | tail -c 60).log 2>&1; }
run --resets-seed 3000 --episodes 10 --placement-spread-cm 3 --out $o/E2p_scripted &
run $T --resets-seed 3000 --episodes 10 --placement-spread-cm 3 --out $o/E2p_teleop; wait
run --states 0-9 --object-shift-cm 4 --object-shift-pattern cross --out $o/E3_scripted &
run $T --states 0-9 --object-shift-cm 4 --object-shift-pattern cross --out $o/E3_teleop; wait
run --resets-seed 3000 --episodes 10 --out $o/E2_scripted &
run $T --resets-seed 3000 --episodes 10 --out $o/E2_teleop; wait
run --states 1-9 --out $o/E1_scripted &
run $T --states 1-9 --out $o/E1_teleop; wait
date -u > logs/chain.done
