#!/bin/bash
# Looking protocol (docs/research/looking.md; configs/sweeps/libero_object_looking.yaml, commit 23acc29): PredVLA fit_sensory_olt error regression (Table 2) and carried Adam at each shift, target shifts first,
# one core, paired with the exact-open-loop line of chain11.
cd /work/exp84b
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
L=results/libero_object_looking/runs
for c in er_shift2 carried_shift2 er_shift4 carried_shift4 er_shift3 carried_shift3 predvla_reading carried_shift0 er_shift6 carried_shift6 er_shift1 carried_shift1; do
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir $L --configs $c --eval-workers 1 > logs/eval14\_$c.log 2>&1
  echo "$(date -u) $c rc=$?" >> logs/chain14.progress
done
date -u > logs/chain14.done
