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
stop=""; [ -n "${STOP_AT:-}" ] && { stop=$(date -d "$STOP_AT" +%s) || { echo "STOP_AT: not a date: $STOP_AT" >&2; exit 2; }; }
export MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
SWEEP=configs/sweeps/libero_four_suites.yaml
R=results/libero_four_suites/runs
LOG=$R/logs/chains/four_suites.progress
mkdir -p $R/logs/chains
step() {  # step NAME SWEEP_FLAGS...: one sweep call; the chain ends at the first that fails
  local name=$1 rc; shift
  if [ -n "$stop" ] && [ "$(date +%s)" -ge "$stop" ]; then echo "$(date -u) stop: $name not started" >> $LOG; exit 0; fi
  echo "$(date -u) start $name" >> $LOG
  predvla sweep $SWEEP --runs-dir $R "$@" ${stop:+--stop-at "$(date -d "@$stop" -Iminutes)"} \
    >> $R/logs/chains/four_suites.$name.log 2>&1
  rc=$?
  echo "$(date -u) end $name rc=$rc" >> $LOG
  [ $rc -eq 0 ] || exit $rc
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
