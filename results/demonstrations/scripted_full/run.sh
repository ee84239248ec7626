#!/bin/bash
# D1 at full scale (configs/sweeps/libero_object_demos_scripted_full.yaml): nothing to train, so it runs on any
# machine after `make libero`. Run from the root of a worktree at a fixed commit: it copies the finished trainings'
# records as the sweep file's header says (once), then evaluates the 16 cells, two task parts at once, E3 before E2
# and exact open loop before error regression in each; every cell resumes task by task. No cell and no task part
# (`predvla sweep --stop-at`) is started after STOP_AT (any date that `date -d` reads, e.g. "01:00 tomorrow"), if given.
set -u
stop=""; [ -n "${STOP_AT:-}" ] && { stop=$(date -d "$STOP_AT" +%s) || { echo "STOP_AT: not a date: $STOP_AT" >&2; exit 2; }; }
export MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
SWEEP=configs/sweeps/libero_object_demos_scripted_full.yaml
R=results/demonstrations/scripted_full/runs
LOG=$R/logs/chains/d1full_chain.progress
mkdir -p $R/logs/chains
if [ ! -d $R/train ]; then
  mkdir -p $R/train
  cp -r results/libero_object_reading/runs/train/predvla_reading $R/train/
  for c in predvla_table2 B1 B2; do cp -r results/libero_object_table2/runs/train/$c $R/train/; done
  sed -i 's#"\.\./\.\./\.\./checkpoints/#"../../../../checkpoints/#' $R/train/*/libero_object/seed*/predvla_sweep_train.json
fi
for c in olt_open_loop_shifted table2_open_loop_shifted B1_shifted B2_shifted olt_carried_shifted olt_shifted \
    table2_carried_shifted table2_shifted olt_open_loop_resets table2_open_loop_resets B1 B2 olt_carried_resets \
    predvla_reading table2_carried_resets predvla_table2; do
  if [ -n "$stop" ] && [ "$(date +%s)" -ge "$stop" ]; then echo "$(date -u) stop: $c not started" >> $LOG; exit 0; fi
  echo "$(date -u) start $c" >> $LOG
  predvla sweep $SWEEP --runs-dir $R --configs $c --eval-workers 2 ${stop:+--stop-at "$(date -d "@$stop" -Iminutes)"} \
    >> $R/logs/chains/d1full_chain.$c.log 2>&1
  echo "$(date -u) end $c rc=$?" >> $LOG
done
