# Sourced (from the repository root, `source results/chain.sh || exit 2`) by the run scripts under results/: the runs'
# environment, STOP_AT parsed once, the check made before each step, one `predvla sweep` step, and the guard of a
# step that would remake a committed dataset.
#   Environment: offscreen rendering, one intra-op thread per process, and OpenBLAS's AVX-512 kernels (SkylakeX)
#       pinned where the processor has them: the committed datasets were made under them, and a data stage remakes a
#       dataset bit for bit only under the kernels it was made under. Elsewhere they would stop every process on an
#       illegal instruction, so OPENBLAS_CORETYPE is unset and OpenBLAS picks its own. CHAIN_CPUINFO (default
#       /proc/cpuinfo) is where the processor's flags are read.
#   chain_stop      STOP_AT in seconds since the epoch, or empty when STOP_AT is unset; a bare HH:MM already past
#                   today means the next one, as `predvla sweep --stop-at` reads it
#   chain_stop_at   `--stop-at` and STOP_AT in ISO 8601, or nothing: pass as "${chain_stop_at[@]}"
#   chain_stopped NAME   true once STOP_AT has passed, after printing that NAME was not started
#   chain_step NAME SWEEP_ARGS...   `predvla sweep SWEEP_ARGS... --stop-at` unless STOP_AT has passed (then the
#       script ends); its output to $chain_prefix.NAME.log, its start and end to $chain_prefix.progress; the
#       script ends at the first step that fails. Set chain_prefix (a path without extension) first.
#   chain_same_data NAME DIR   ends the script before step NAME where DIR (a dataset the step's data stage would
#       make) is missing and this processor cannot remake it bit for bit, unless ALLOW_OTHER_KERNELS=1 (a dataset of
#       the same seeds that differs in floating-point details is then made, and its stage record names the kernels).
export MUJOCO_GL=egl OMP_NUM_THREADS=1
if grep -qw avx512bw "${CHAIN_CPUINFO:-/proc/cpuinfo}" 2>/dev/null; then
  chain_avx512=1
  export OPENBLAS_CORETYPE=SkylakeX
else
  chain_avx512=0
  unset OPENBLAS_CORETYPE
  echo "chain: no AVX-512 here, OpenBLAS picks its kernels: a data stage run here does not remake a committed" \
    "dataset bit for bit (evaluations run on the same starts either way)" >&2
fi
chain_stop=""
chain_stop_at=()
if [ -n "${STOP_AT:-}" ]; then
  chain_stop=$(date -d "$STOP_AT" +%s) || { echo "STOP_AT: not a date: $STOP_AT" >&2; exit 2; }
  if [[ $STOP_AT =~ ^[0-9]{1,2}:[0-9]{2}$ ]] && [ "$chain_stop" -le "$(date +%s)" ]; then
    chain_stop=$((chain_stop + 86400))
  fi
  chain_stop_at=(--stop-at "$(date -d "@$chain_stop" -Iseconds)")
fi
chain_stopped() {
  [ -n "$chain_stop" ] && [ "$(date +%s)" -ge "$chain_stop" ] || return 1
  echo "$(date -u) stop: $1 not started"
}
chain_step() {
  local name=$1 rc
  shift
  mkdir -p "$(dirname "$chain_prefix")"
  if chain_stopped "$name" >> "$chain_prefix.progress"; then
    echo "chain: STOP_AT passed, $name and the steps after it not started" >&2
    exit 0
  fi
  echo "$(date -u) start $name $*" >> "$chain_prefix.progress"
  predvla sweep "$@" "${chain_stop_at[@]}" >> "$chain_prefix.$name.log" 2>&1
  rc=$?
  echo "$(date -u) end $name rc=$rc" >> "$chain_prefix.progress"
  [ $rc -eq 0 ] || exit $rc
}
chain_same_data() {
  local name=$1 dir=$2
  [ -e "$dir" ] || [ "$chain_avx512" = 1 ] || [ "${ALLOW_OTHER_KERNELS:-0}" = 1 ] && return 0
  mkdir -p "$(dirname "$chain_prefix")"
  echo "$(date -u) stop: $name not started: it would make $dir, which this processor (no AVX-512) cannot make" \
    "bit for bit as it was made; run it where AVX-512 is, or set ALLOW_OTHER_KERNELS=1" \
    | tee -a "$chain_prefix.progress" >&2
  exit 3
}
