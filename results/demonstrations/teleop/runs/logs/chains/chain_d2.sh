#!/bin/bash
# D2 screen (teleop, LIBERO's own placements), this sitting, from a worktree at fe5371f: the data stage (tasks 2, 3
# and 6's files were made by `predvla demos` with the D2 sweep's own arguments from 33851b8, whose demonstration code
# is the same; copied, the stage makes the other seven), then Table 2 literal's and BC-Transformer's trainings on both
# cores, then their exact-open-loop / E1 cells (one core each), then BC-RNN's training.
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop.yaml
R=results/demonstrations/teleop/runs
p() { echo "$(date -u) $*" >> logs/chain_d2.progress; }
p start $(git log --oneline -1)
predvla sweep $S --runs-dir $R --data-only > logs/data.log 2>&1; p data rc=$?
for c in table2 B1; do
  predvla sweep $S --runs-dir $R --configs $c --train-only > logs/train_$c.log 2>&1; p train $c rc=$?
done
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_$1.log 2>&1; p eval $1 rc=$?; }
cell table2_open_loop & cell B1 & wait
predvla sweep $S --runs-dir $R --configs B2 --train-only > logs/train_B2.log 2>&1; p train B2 rc=$?
date -u > logs/chain_d2.done
