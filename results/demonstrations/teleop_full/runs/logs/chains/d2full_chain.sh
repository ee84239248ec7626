#!/bin/bash
# D2 at full scale (configs/sweeps/libero_object_demos_teleop_full.yaml), from the worktree at 4f9d76b8 whose
# outputs/libero_object_teleop links to D2's dataset: fit_sensory_olt's training (resumed from its last checkpoint when
# one exists), then its nine evaluation cells with the target sets first (E3 shifted, E2 randomised resets, E1 official
# states; exact open loop before error regression in each), then BC-RNN's training and its three cells. Every step
# resumes where a kill left it (training: the last of its 1,000-step checkpoints; evaluation: task by task). A step is
# not started after STOP_AT (any date that `date -d` reads, e.g. "01:00 tomorrow"), if given.
cd /work/exp_d2full || exit 1
stop=""; [ -n "${STOP_AT:-}" ] && { stop=$(date -d "$STOP_AT" +%s) || { echo "STOP_AT: not a date: $STOP_AT" >&2; exit 2; }; }
source /work/main/.venv/bin/activate
export PYTHONPATH=/work/exp_d2full MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
SWEEP=configs/sweeps/libero_object_demos_teleop_full.yaml
RUNS=results/demonstrations/teleop_full/runs
LOG=$RUNS/logs/chains/d2full_chain.progress
step() {  # step CONFIGS [sweep flags]
  if [ -n "$stop" ] && [ "$(date +%s)" -ge "$stop" ]; then echo "$(date -u) stop: $1 not started" >> $LOG; exit 0; fi
  echo "$(date -u) start $*" >> $LOG
  predvla sweep $SWEEP --runs-dir $RUNS --configs "$@" >> $RUNS/logs/chains/d2full_chain.$1.log 2>&1
  echo "$(date -u) end $1 rc=$?" >> $LOG
}
step olt --train-only
for c in olt_open_loop_shifted olt_carried_shifted olt_shifted olt_open_loop_resets olt_carried_resets olt_resets \
    olt_open_loop olt_carried olt; do
  step $c --eval-workers 2
done
step B2 --train-only
for c in B2_shifted B2_resets B2; do step $c --eval-workers 2; done
