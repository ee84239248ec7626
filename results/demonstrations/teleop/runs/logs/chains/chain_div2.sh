#!/bin/bash
# After chain_d3e2.sh, one core: the mean plan at diversity 0.25 (the same diagnostic as chain_div.sh's 0.5, added
# after 0.5's result: its mean failed on tasks 2 and 3, so the break lies below 0.5).
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
C=results/demonstrations/teleop/runs/logs/chains
p() { echo "$(date -u) $*" >> $C/chain_d2.progress; }
while pgrep -f chain_d3e2.sh > /dev/null; do sleep 20; done
D=results/demonstrations/diversity
common="--suite libero_object --seed 0 --init-noise 0.02 --half-turn wrist_centre --hold-steps 0 --style teleop"
predvla demos $common --tasks 2,3,6 --per-task 50 --render-interval 1000 --diversity 0.25 \
  --out outputs/libero_object_teleop_d025/hdf5 > logs/div_demos_d025.log 2>&1; p demos d0.25 rc=$?
python -m research.divergence.mean_plan --hdf5-root outputs/libero_object_teleop_d025/hdf5 --tasks 2,3,6 \
  --states 0-9 --out $D/mean_plan_d025 > logs/div_mean_plan_d025.log 2>&1; p mean_plan d0.25 rc=$?
python -m research.dataset_stats outputs/libero_object_teleop_d025/hdf5/libero_object --label "teleop, diversity 0.25, tasks 2, 3, 6" \
  --out $D/dataset_stats_d025.json > logs/div_stats_d025.log 2>&1; p dataset_stats d0.25 rc=$?
p chain_div2 done
