#!/bin/bash
# Looking protocol (docs/research/looking.md; configs/sweeps/libero_object_looking.yaml, commit 23acc29), one core,
# after chain13's first cell (b1_shift4): the rest of BC-Transformer's line, PredVLA fit_sensory_olt's exact open
# loop on the variants, then BC-RNN at the shifts the targets name (4, 2 cm).
cd /work/exp84b
while pgrep -f "configs b1_shift4" > /dev/null; do sleep 15; done
echo "$(date -u) b1_shift4 finished" >> logs/chain16.progress
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp84b MUJOCO_GL=egl OMP_NUM_THREADS=1
L=results/libero_object_looking/runs
for c in b1_shift2 B1 b1_shift6 b1_shift1 b1_shift3 ol_pro_temp_x01 ol_pro_temp_y01 ol_pro_swap ol_pro_lan \
         ol_pro_with_yellow_book ol_plus_language_1 ol_pro_temp_x02 ol_pro_temp_y02 b2_shift4 b2_shift2 B2 \
         b2_shift6 b2_shift1 b2_shift3; do
  predvla sweep configs/sweeps/libero_object_looking.yaml --runs-dir $L --configs $c --eval-workers 1 > logs/eval16_$c.log 2>&1
  echo "$(date -u) $c rc=$?" >> logs/chain16.progress
done
date -u > logs/chain16.done
