# Sourced (from the repository root) by the run scripts under results/: STOP_AT, any date that `date -d` reads
# (e.g. "01:00 tomorrow"), parsed once, the check made before each step, and one `predvla sweep` step; the runs'
# environment (offscreen rendering, one intra-op thread per process, and OpenBLAS's AVX-512 kernels pinned where the
# processor has them: the committed datasets were made under them, and a data stage regenerates bit for bit only under
# the kernels it was made under; forced on a processor without AVX-512 they would stop every process on an illegal
# instruction).
#   chain_stop      STOP_AT in seconds since the epoch, or empty when STOP_AT is unset
#   chain_stop_at   `predvla sweep --stop-at` and its ISO 8601 value, or nothing: pass as "${chain_stop_at[@]}"
#   chain_stopped NAME   true once STOP_AT has passed, after printing that NAME was not started
#   chain_step NAME SWEEP_ARGS...   `predvla sweep SWEEP_ARGS... --stop-at` unless STOP_AT has passed (then the
#       script ends); its output to $chain_prefix.NAME.log, its start and end to $chain_prefix.progress; the
#       script ends at the first step that fails. Set chain_prefix (a path without extension) first.
export MUJOCO_GL=egl OMP_NUM_THREADS=1
if grep -qw avx512bw /proc/cpuinfo 2>/dev/null; then
  export OPENBLAS_CORETYPE=SkylakeX
else
  echo "chain: no AVX-512 here, OpenBLAS picks its kernels: a data stage run here will not regenerate a committed" \
    "dataset bit for bit (evaluations run on the same starts either way)" >&2
fi
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
