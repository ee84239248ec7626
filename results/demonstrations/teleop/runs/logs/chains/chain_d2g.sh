#!/bin/bash
# D2's evaluation cells from the committed models, one core, after chain_d2e.sh: Table 2 literal with the carried Adam on E3, then Table 2's error regression on E2.
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop.yaml
R=results/demonstrations/teleop/runs
p() { echo "$(date -u) $*" >> results/demonstrations/teleop/runs/logs/chains/chain_d2.progress; }
while pgrep -f chain_d2e.sh > /dev/null; do sleep 20; done
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_$1.log 2>&1; p eval $1 rc=$?; }
for c in table2_carried_shifted table2_resets; do cell $c; done
p chain_d2g done
