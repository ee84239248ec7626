# Sourced (from the repository root) by the run scripts under results/: STOP_AT, any date that `date -d` reads
# (e.g. "01:00 tomorrow"), parsed once, the check made before each step, and one `predvla sweep` step; the runs'
# environment (offscreen rendering, one intra-op thread per process, OpenBLAS's kernels fixed so that data stages
# regenerate bit for bit).
#   chain_stop      STOP_AT in seconds since the epoch, or empty when STOP_AT is unset
#   chain_stop_at   `predvla sweep --stop-at` and its ISO 8601 value, or nothing: pass as "${chain_stop_at[@]}"
#   chain_stopped NAME   true once STOP_AT has passed, after printing that NAME was not started
#   chain_step NAME SWEEP_ARGS...   `predvla sweep SWEEP_ARGS... --stop-at` unless STOP_AT has passed (then the
#       script ends); its output to $chain_prefix.NAME.log, its start and end to $chain_prefix.progress; the
#       script ends at the first step that fails. Set chain_prefix (a path without extension) first.
export MUJOCO_GL=egl OMP_NUM_THREADS=1 OPENBLAS_CORETYPE=SkylakeX
chain_stop=""
chain_stop_at=()
if [ -n "${STOP_AT:-}" ]; then
  chain_stop=$(date -d "$STOP_AT" +%s) || { echo "STOP_AT: not a date: $STOP_AT" >&2; exit 2; }
  chain_stop_at=(--stop-at "$(date -d "@$chain_stop" -Iminutes)")
fi
chain_stopped() {
  [ -n "$chain_stop" ] && [ "$(date +%s)" -ge "$chain_stop" ] || return 1
  echo "$(date -u) stop: $1 not started"
}
chain_step() {
  local name=$1 rc
  shift
  mkdir -p "$(dirname "$chain_prefix")"
  chain_stopped "$name" >> "$chain_prefix.progress" && exit 0
  echo "$(date -u) start $name $*" >> "$chain_prefix.progress"
  predvla sweep "$@" "${chain_stop_at[@]}" >> "$chain_prefix.$name.log" 2>&1
  rc=$?
  echo "$(date -u) end $name rc=$rc" >> "$chain_prefix.progress"
  [ $rc -eq 0 ] || exit $rc
}
