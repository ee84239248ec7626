#!/bin/bash
# Branch the Table 2 seed-0 run at checkpoint STEP into outputs/table2_branches/NAME, change train_config.json's
# optimizer fields given as KEY=VALUE (e.g. grad_clip_norm=100), train to END, 2 DDP processes.
set -euo pipefail
NAME=$1 STEP=$2 END=$3; shift 3
cd /work/main
SRC=results/libero_object_table2/runs/train/predvla_table2/libero_object/seed0/checkpoints/$(printf %06d $STEP)
OUT=/work/main/outputs/table2_branches/$NAME
mkdir -p $OUT/checkpoints
cp -r $SRC $OUT/checkpoints/
ln -sfn $(printf %06d $STEP) $OUT/checkpoints/last
.venv/bin/python - "$OUT" "$NAME" "$END" "$@" <<'PY'
import json, sys
from pathlib import Path
from lerobot_predvla.utils.manifest import write_manifest
out, name, end, *changes = sys.argv[1:]
pm = Path(out) / "checkpoints" / "last" / "pretrained_model"
tc = json.loads((pm / "train_config.json").read_text())
cfg = json.loads((pm / "config.json").read_text())
tc["output_dir"], tc["job_name"], tc["steps"] = out, f"predvla_table2_{name}", int(end)
for change in changes:
    key, value = change.split("=")
    value = json.loads(value)
    if key in tc["optimizer"]:
        tc["optimizer"][key] = value
    if key in tc["policy"]:
        tc["policy"][key] = value
        cfg[key] = value
(pm / "train_config.json").write_text(json.dumps(tc, indent=4))
(pm / "config.json").write_text(json.dumps(cfg, indent=4))
write_manifest(pm)
print("branch", name, "from", pm, "changes", changes)
PY
export MUJOCO_GL=egl OMP_NUM_THREADS=1 PYTHONPATH=/work/runs/code
nohup setsid .venv/bin/torchrun --master_port=29517 --nproc_per_node=2 .venv/bin/lerobot-train \
  --config_path=$OUT/checkpoints/last/pretrained_model/train_config.json --resume=true > $OUT/train.log 2>&1 &
echo launched
