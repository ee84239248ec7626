#!/bin/bash
# End of the sitting: BC-RNN on E1 and Table 2 literal's exact open loop on E3 (object moved 4 cm), one core each.
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop.yaml
R=results/demonstrations/teleop/runs
p() { echo "$(date -u) $*" >> logs/chain_d2.progress; }
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_$1.log 2>&1; p eval $1 rc=$?; }
cell B2 & cell table2_open_loop_shifted & wait
