#!/bin/bash
# Replaces chain_d2.sh after its data stage, with the trainings first (they need the dataset, which stays on this
# machine; evaluations need only the committed models): waits for Table 2 literal's training (started by
# chain_d2.sh), then BC-Transformer's and BC-RNN's trainings on both cores, then the exact-open-loop / E1 cells of
# Table 2 literal and BC-Transformer (one core each).
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
S=configs/sweeps/libero_object_demos_teleop.yaml
R=results/demonstrations/teleop/runs
p() { echo "$(date -u) $*" >> logs/chain_d2.progress; }
while pgrep -f "$S --runs-dir $R --configs table2 --train-only" > /dev/null; do sleep 20; done
p train table2 ended, published: $(ls checkpoints/demonstrations/teleop/ 2>/dev/null | tr '\n' ' ')
for c in B1 B2; do
  predvla sweep $S --runs-dir $R --configs $c --train-only > logs/train_$c.log 2>&1; p train $c rc=$?
done
cell() { predvla sweep $S --runs-dir $R --configs $1 --eval-workers 1 > logs/eval_$1.log 2>&1; p eval $1 rc=$?; }
cell table2_open_loop & cell B1 & wait
date -u > logs/chain_d2.done
