#!/bin/bash
# After Table 2 literal's exact-open-loop cell on E1 (chain_d2b.sh): where that model's exact open loop leaves D2's
# demonstrations, from their own starts, as measured for D3's models (demonstrations.md, "Why D3's exact open loop
# fails"): `research.divergence`, tasks 2, 3 and 6, 3 demonstrations each, one core.
cd /work/exp_d2
while ! grep -q "eval table2_open_loop rc" logs/chain_d2.progress 2>/dev/null; do sleep 20; done
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
start=$(date +%s)
python -m research.divergence --checkpoint checkpoints/demonstrations/teleop/table2_seed0 \
  --hdf5-root outputs/libero_object_teleop/hdf5 --tasks 2,3,6 --demos 3 \
  --out results/demonstrations/teleop/divergence/table2 > logs/divergence_table2.log 2>&1
echo "$(date -u) divergence table2 rc=$? wall $(( $(date +%s) - start )) s" >> logs/chain_d2.progress
