#!/bin/bash
# After chain10's second line (fit_sensory_olt's Table 2 ER on D3's E2): the looking protocol's exact-open-loop line
# (docs/research/looking.md; configs/sweeps/libero_object_looking.yaml, commit 23acc29), PredVLA fit_sensory_olt
# seed 0 in exact open loop at each shift, the shifts the targets name first (4, 2 cm), one core.
cd /work/exp84b
while ! grep -q " olt_resets rc" logs/chain10.progress 2>/dev/null; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
L=results/libero_object_looking/runs
mkdir -p $L/train
[ -e $L/train/predvla_reading ] || ln -s ../../../libero_object_reading/runs/train/predvla_reading $L/train/
for c in ol_shift4 ol_shift2 ol_shift0 ol_shift6 ol_shift1 ol_shift3; do
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir $L --configs $c --eval-workers 1 > logs/eval11_$c.log 2>&1
  echo "$(date -u) $c rc=$?" >> logs/chain11.progress
done
date -u > logs/chain11.done
