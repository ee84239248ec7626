#!/bin/bash
# D2's evaluation cells from the committed models (no dataset needed), one core: Table 2 literal with Table 2's error regression on E1 and E3, then E2's exact open loop and BC-Transformer.
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop.yaml
R=results/demonstrations/teleop/runs
p() { echo "$(date -u) $*" >> results/demonstrations/teleop/runs/logs/chains/chain_d2.progress; }
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_$1.log 2>&1; p eval $1 rc=$?; }
for c in table2 table2_shifted table2_open_loop_resets B1_resets; do cell $c; done
p chain_d2e done
