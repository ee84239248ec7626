#!/bin/bash
# D2 at full scale (configs/sweeps/libero_object_demos_teleop_full.yaml): fit_sensory_olt's nine evaluation cells, E3
# (object shifted 4 cm, the set on which the targets are judged) first, then E1 (official init states: the
# dataset's headline row) and E2 (randomised resets), exact open loop before error regression in each; then BC-RNN's
# training and its three cells. The chain that trained the model (runs/logs/chains/d2full_chain.sh) had E2 before E1;
# E3's cells settled both targets before E1 or E2 ran, and the order changes no episode. fit_sensory_olt's model is
# committed and its training record is in runs/train, so its cells run on any machine after `make libero`. BC-RNN's
# training needs D2 (outputs/libero_object_teleop), which the sweep's data stage remakes bit for bit only on a
# processor with AVX-512: elsewhere the chain ends before it (results/chain.sh, chain_same_data). Run from the root of
# a worktree at a fixed commit; every step resumes where a kill left it (evaluations task by task, training from its
# last 1,000-step checkpoint), and the chain ends at the first step that fails. No step and no part of one (`predvla
# sweep --stop-at`) is started after STOP_AT (any date that `date -d` reads, e.g. "01:00 tomorrow"), if given.
set -u
source results/chain.sh || exit 2
SWEEP=configs/sweeps/libero_object_demos_teleop_full.yaml
R=results/demonstrations/teleop_full/runs
chain_prefix=$R/logs/chains/d2full_chain
for c in olt_open_loop_shifted olt_carried_shifted olt_shifted olt_open_loop olt_carried olt olt_open_loop_resets \
    olt_carried_resets olt_resets; do
  chain_step $c $SWEEP --runs-dir $R --configs $c --eval-workers 2
done
chain_same_data B2_train outputs/libero_object_teleop/dataset_features
chain_step B2_train $SWEEP --runs-dir $R --configs B2 --train-only
for c in B2_shifted B2_resets B2; do chain_step $c $SWEEP --runs-dir $R --configs $c --eval-workers 2; done
