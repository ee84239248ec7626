#!/bin/bash
# D2's dataset remade bit for bit (OPENBLAS_CORETYPE=SkylakeX, the kernels it was made under;
# results/demonstrations/check_openblas.txt) for fit_sensory_olt's training, from a worktree at 74f90b8, on one core
# (the other runs the looking protocol's chain19.sh): the demonstrations of all ten tasks in one process (the sweep's
# data stage would run two), then the sweep's own front end and conversion, then the fingerprint against D2's.
cd /work/exp_d2olt
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2olt MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
P=results/demonstrations/teleop/runs/logs/chains/chain_d2_olt.progress
while pgrep -f "runs-dir results/libero_object_looking/runs --configs predvla_reading" > /dev/null; do sleep 30; done
echo "$(date -u) start demos" >> $P
predvla demos --suite libero_object --tasks 0,2,4,6,8,1,3,5,7,9 --per-task 50 --render-interval 4 --seed 0 \
  --init-noise 0.02 --half-turn wrist_centre --hold-steps 0 --style teleop --diversity 1.0 \
  --out /work/exp_d2olt/outputs/libero_object_teleop/hdf5 > logs/d2_demos.log 2>&1
echo "$(date -u) demos rc=$?" >> $P
predvla sweep configs/sweeps/libero_object_demos_teleop.yaml --runs-dir results/demonstrations/teleop/runs \
  --data-only > logs/d2_data.log 2>&1
echo "$(date -u) data-only rc=$?" >> $P
python results/libero_object_reading_machines/regeneration/fingerprint.py \
  outputs/libero_object_teleop/hdf5/libero_object > logs/d2_fingerprint.json 2> logs/d2_fingerprint.err
echo "$(date -u) fingerprint rc=$?" >> $P
