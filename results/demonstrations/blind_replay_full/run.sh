#!/bin/bash
# The blind-replay figure of each full-scale evaluation set (docs/research/demonstrations.md, "Full scale: the
# blind-replay figures"): the screen's commands on all ten tasks and 20 episodes per task and set, in the order the
# full-scale cells need them (E3 and E1 of the teleop plan for D2, E3 of the scripted plan for D1, D3's E2p, then the
# rest). Physics only, one core; every set resumes task by task. Run from the repository root (or a worktree) after
# `make libero`; a set is not started after STOP_AT (any date that `date -d` reads, e.g. "01:00 tomorrow"), if given.
set -u
source results/chain.sh || exit 2
o=results/demonstrations/blind_replay_full
replay() {  # replay SET STYLE [flags]
  local set=$1 style=$2; shift 2
  chain_stopped ${set}_$style && exit 0
  local b=(predvla blind-replay --suites libero_object --tasks 0-9 --style "$style")
  [ "$style" = teleop ] && b+=(--diversity 1)
  echo "$(date -u) start ${set}_$style"
  "${b[@]}" "$@" --out "$o/${set}_$style" || exit 1
}
replay E3 teleop --states 0-19 --object-shift-cm 4 --object-shift-pattern cross
replay E1 teleop --states 1-19
replay E3 scripted --states 0-19 --object-shift-cm 4 --object-shift-pattern cross
replay E2p teleop --resets-seed 3000 --episodes 20 --placement-spread-cm 3
replay E1 scripted --states 1-19
for style in teleop scripted; do replay E2 $style --resets-seed 3000 --episodes 20; done
