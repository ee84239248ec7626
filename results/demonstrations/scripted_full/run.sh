#!/bin/bash
# D1 at full scale (configs/sweeps/libero_object_demos_scripted_full.yaml): nothing to train, so it runs on any
# machine after `make libero`. Run from the root of a worktree at a fixed commit: it copies the finished trainings'
# records as the sweep file's header says (once), then evaluates the 16 cells, two task parts at once, E3 before E2
# and exact open loop before error regression in each; every cell resumes task by task, and the chain ends at the
# first cell that fails. No cell and no task part (`predvla sweep --stop-at`) is started after STOP_AT (any date that
# `date -d` reads, e.g. "01:00 tomorrow"), if given.
set -u
source results/chain.sh || exit 2
SWEEP=configs/sweeps/libero_object_demos_scripted_full.yaml
R=results/demonstrations/scripted_full/runs
chain_prefix=$R/logs/chains/d1full_chain
if [ ! -d $R/train ]; then
  mkdir -p $R/train
  cp -r results/libero_object_reading/runs/train/predvla_reading $R/train/
  for c in predvla_table2 B1 B2; do cp -r results/libero_object_table2/runs/train/$c $R/train/; done
  sed -i 's#"\.\./\.\./\.\./checkpoints/#"../../../../checkpoints/#' $R/train/*/libero_object/seed*/predvla_sweep_train.json
fi
for c in olt_open_loop_shifted table2_open_loop_shifted B1_shifted B2_shifted olt_carried_shifted olt_shifted \
    table2_carried_shifted table2_shifted olt_open_loop_resets table2_open_loop_resets B1 B2 olt_carried_resets \
    predvla_reading table2_carried_resets predvla_table2; do
  chain_step $c $SWEEP --runs-dir $R --configs $c --eval-workers 2
done
