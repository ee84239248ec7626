#!/bin/bash
# D3's last protocol cells on E2 (randomised resets of seed 3000), from the committed models, one core, after
# chain_d2h.sh: Table 2 literal, then fit_sensory_olt, with the carried Adam.
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop_placed.yaml
R=results/demonstrations/teleop_placed/runs
p() { echo "$(date -u) $*" >> results/demonstrations/teleop/runs/logs/chains/chain_d2.progress; }
while pgrep -f chain_d2h.sh > /dev/null; do sleep 20; done
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_d3_$1.log 2>&1; p eval D3 $1 rc=$?; }
for c in table2_carried_resets olt_carried_resets; do cell $c; done
p chain_d3e2 done
