#!/bin/bash
# After chain_d2g.sh, one core: the mean plan at diversity 0.5 (docs/research/demonstrations.md, "How much timing
# variation the mean survives"), first the check that the render interval leaves the actions unchanged; then the
# looking protocol's carried Adam at 3 cm (results/libero_object_looking/runs/logs/chains/).
cd /work/exp_d2
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2 MUJOCO_GL=egl OMP_NUM_THREADS=1
C=results/demonstrations/teleop/runs/logs/chains
p() { echo "$(date -u) $*" >> $C/chain_d2.progress; }
while pgrep -f chain_d2g.sh > /dev/null; do sleep 20; done
D=results/demonstrations/diversity
mkdir -p $D
common="--suite libero_object --seed 0 --init-noise 0.02 --half-turn wrist_centre --hold-steps 0 --style teleop"
predvla demos $common --tasks 2 --per-task 2 --render-interval 1000 --diversity 1.0 --out outputs/check_ri/hdf5 \
  > logs/div_check.log 2>&1
python - > $D/check_render_interval.txt 2>&1 <<'PY'
import hashlib, json
from pathlib import Path
import h5py
ref = json.load(open("results/demonstrations/teleop/fingerprint.json"))["files"]
for path in sorted(Path("outputs/check_ri/hdf5/libero_object").glob("*.hdf5")):
    with h5py.File(path, "r") as f:
        for demo in sorted(f["data"]):
            for key in ("actions", "states"):
                got = hashlib.sha256(f[f"data/{demo}/{key}"][()].tobytes()).hexdigest()[:16]
                want = ref[path.name][demo][key]
                print(path.name, demo, key, got, "==" if got == want else "!=", want)
PY
p check_render_interval: $(grep -c "==" $D/check_render_interval.txt) equal, $(grep -c "!=" $D/check_render_interval.txt) different
predvla demos $common --tasks 2,3,6 --per-task 50 --render-interval 1000 --diversity 0.5 \
  --out outputs/libero_object_teleop_d05/hdf5 > logs/div_demos.log 2>&1; p demos d0.5 rc=$?
python -m research.divergence.mean_plan --hdf5-root outputs/libero_object_teleop_d05/hdf5 --tasks 2,3,6 \
  --states 0-9 --out $D/mean_plan_d05 > logs/div_mean_plan.log 2>&1; p mean_plan d0.5 rc=$?
python -m research.dataset_stats outputs/libero_object_teleop_d05/hdf5/libero_object --label "teleop, diversity 0.5, tasks 2, 3, 6" \
  --out $D/dataset_stats_d05.json > logs/div_stats.log 2>&1; p dataset_stats d0.5 rc=$?
S=configs/sweeps/libero_object_looking.yaml
predvla sweep $S --runs-dir results/libero_object_looking/runs --configs carried_shift3 --eval-workers 1 \
  > logs/eval_look_carried_shift3.log 2>&1; p eval looking carried_shift3 rc=$?
p chain_div done
