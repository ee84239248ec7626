# Sourced (from the repository root) by the run scripts under results/: STOP_AT, any date that `date -d` reads
# (e.g. "01:00 tomorrow"), parsed once, and the check made before each step.
#   chain_stop      STOP_AT in seconds since the epoch, or empty when STOP_AT is unset
#   chain_stop_at   `predvla sweep --stop-at` and its ISO 8601 value, or nothing: pass as "${chain_stop_at[@]}"
#   chain_stopped NAME   true once STOP_AT has passed, after printing that NAME was not started
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
