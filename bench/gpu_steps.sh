# The steps of a timed GPU run, sourced by gpu_check.sh and perf_gpu_run.sh (staged beside them):
# each step runs under `timeout` within what is left of the run's budget and leaves its output in
# $OUT/NAME.log and a line in $SUMMARY. Needs HERE (the staged folder), OUT and BUDGET; makes OUT
# absolute and sets SUMMARY (OUT/summary.txt, emptied), START and COMMIT (HERE/COMMIT).
#   STEP_SIGNAL: the signal `timeout` sends first (default TERM; INT lets perf stop at its next
#   iteration with a consistent workspace), KILL 15 s later.

mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
SUMMARY=$OUT/summary.txt
: > "$SUMMARY"
START=$(date +%s)
COMMIT=$(cat "$HERE/COMMIT" 2>/dev/null || echo unknown)

left() { echo $((BUDGET - ($(date +%s) - START))); }

# step NAME CAP COMMAND...: runs COMMAND for at most min(CAP, time left - 10) seconds, output in
# $OUT/NAME.log, one line in summary.txt. Sets STEP_RC (124: timed out; 99: not run, no time).
step() {
  local name=$1 cap=$2
  shift 2
  local l t t0 t1
  l=$(left)
  t=$((cap < l - 10 ? cap : l - 10))
  if [ "$t" -lt 15 ]; then
    STEP_RC=99
    printf '%-9s not run: %d s left of the %d s budget\n' "$name" "$l" "$BUDGET" | tee -a "$SUMMARY"
    return
  fi
  echo "== $name (cap $t s): $*"
  t0=$(date +%s%N)
  timeout -s "${STEP_SIGNAL:-TERM}" -k 15 "$t" "$@" > "$OUT/$name.log" 2>&1
  STEP_RC=$?
  t1=$(date +%s%N)
  printf '%-9s rc=%-3d %6.1f s (cap %d s)\n' "$name" "$STEP_RC" "$(((t1 - t0) / 1000000))e-3" "$t" | tee -a "$SUMMARY"
  tail -n 4 "$OUT/$name.log" | sed 's/^/    /'
}

verdict=PASS
fail() {
  verdict=FAIL
  echo "FAIL: $*" | tee -a "$SUMMARY"
}

