#!/bin/bash
# D3 at full scale (configs/sweeps/libero_object_demos_teleop_placed_full.yaml): the data stage where
# outputs/libero_object_teleop_placed lacks D3 (about 1.5 h of both cores; only on a processor with AVX-512, which
# remakes the screen's D3 bit for bit, or with ALLOW_OTHER_KERNELS=1: results/chain.sh, chain_same_data), Table 2
# literal's training (30,000 steps, two DDP processes of 16), its cells on the target sets first (E3 object shifted 4
# cm, E2p resets with placements varied as D3's; exact open loop, then the carried Adam, then Table 2's update),
# BC-Transformer's training (50,000 steps) and its cells on the same two sets, then the other sets' cells (E2
# randomised resets, E1 official states). Run from the root of a worktree at a fixed commit after `make libero`; every
# step resumes where a kill left it (demonstrations task by task, trainings from their last 1,000-step checkpoint,
# evaluations task by task), and the chain ends at the first step that fails. No step and no part of one (`predvla
# sweep --stop-at`) is started after STOP_AT (any date that `date -d` reads, e.g. "01:00 tomorrow"), if given.
set -u
source results/chain.sh || exit 2
SWEEP=configs/sweeps/libero_object_demos_teleop_placed_full.yaml
R=results/demonstrations/teleop_placed_full/runs
chain_prefix=$R/logs/chains/d3full_chain
step() {  # step NAME SWEEP_FLAGS...
  local name=$1; shift
  chain_step $name $SWEEP --runs-dir $R "$@"
}
chain_same_data data outputs/libero_object_teleop_placed/dataset_features
step data --data-only
step table2_train --configs table2 --train-only
for c in table2_open_loop_shifted table2_carried_shifted table2_shifted table2_open_loop_placed_resets \
    table2_carried_placed_resets table2_placed_resets; do
  step $c --configs $c --eval-workers 2
done
step B1_train --configs B1 --train-only
for c in B1_shifted B1_placed_resets table2_open_loop_resets table2_carried_resets table2_resets table2_open_loop \
    table2_carried table2 B1_resets B1; do
  step $c --configs $c --eval-workers 2
done
