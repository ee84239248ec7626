#!/bin/bash
# The four suites at full scale (configs/sweeps/libero_four_suites.yaml), in the order their questions come: the data
# stage (the demonstrations of all four suites and the one front end fitted on them, about 3.3 h of both cores), then
# per suite, libero_goal first (the suite that tests language), `fit_sensory_olt`'s training (about 3.9 h) and its
# evaluations (exact open loop first, the other instruction on libero_goal, then both error regressions), then the
# BC baselines suite by suite. Run from the root of a worktree at a fixed commit after `make libero`; every step
# resumes where a kill left it (demonstrations task by task, trainings from their last 1,000-step checkpoint,
# evaluations task by task). No step and no part of one (`predvla sweep --stop-at`) is started after STOP_AT (any date
# that `date -d` reads, e.g. "01:00 tomorrow"), if given; progress in runs/logs/chains/four_suites.progress.
set -u
source results/chain.sh || exit 2
SWEEP=configs/sweeps/libero_four_suites.yaml
R=results/libero_four_suites/runs
chain_prefix=$R/logs/chains/four_suites
step() {  # step NAME SWEEP_FLAGS...
  local name=$1; shift
  chain_step $name $SWEEP --runs-dir $R "$@"
}
step data --data-only
for suite in libero_goal libero_spatial libero_10 libero_object; do
  step olt_$suite --suites $suite --configs olt --train-only
  cells="olt_open_loop olt olt_carried"
  [ $suite = libero_goal ] && cells="olt_open_loop olt_open_loop_other_instruction olt olt_carried"
  for cell in $cells; do step ${cell}_$suite --suites $suite --configs $cell --eval-workers 2; done
done
for suite in libero_goal libero_spatial libero_10 libero_object; do
  for baseline in B1 B2; do
    step ${baseline}_$suite --suites $suite --configs $baseline --train-only
    step ${baseline}_${suite}_eval --suites $suite --configs $baseline --eval-workers 2
  done
done
