#!/bin/bash
# Looking protocol (docs/research/looking.md; configs/sweeps/libero_object_looking.yaml, commit 23acc29): BC-Transformer then BC-RNN at each shift,
# one core, paired with the exact-open-loop line of chain11.
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
L=results/libero_object_looking/runs
for c in b1_shift4 b1_shift2 B1 b1_shift6 b1_shift1 b1_shift3 b2_shift4 b2_shift2 B2 b2_shift6 b2_shift1 b2_shift3; do
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir $L --configs $c --eval-workers 1 > logs/eval13\_$c.log 2>&1
  echo "$(date -u) $c rc=$?" >> logs/chain13.progress
done
date -u > logs/chain13.done
