#!/usr/bin/env bash
# Dry run of the one GPU path (stage_gpu_run.sh + gpu_check.sh) on a machine without a GPU:
# stages into a temporary folder (which runs the staging's own checks: libraries, glibc
# versions, size), decodes the photos here with perf_bench_prep --write-u8 (no numpy needed; the
# same bytes as decode_images.py), checks that the benchmark builds every level's rays from the
# staged data (--check-data), then runs the staged gpu_check.sh and checks that it fails the way
# it must without a device: the parity step fails (PERF_REQUIRE_GPU) naming the reason, nothing
# is skipped, the benchmark says there is no CUDA device, the verdict is FAIL and the exit status
# non-zero. Exit 77 (a skip for CTest) where a GPU is visible.
#   usage: bench/gpu_check_dry_run.sh BUILD_DIR     (a CUDA build with perf, perf_bench_prep,
#                                                   perf_bench_gpu and gpu_parity_test built)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=$(cd "${1:?usage: bench/gpu_check_dry_run.sh BUILD_DIR}" && pwd)
source bench/dry_run_lib.sh  # skips where a GPU is; TMP, expect, problems
STAGE=$TMP/gpu_run

t0=$(date +%s)
STAGE=$STAGE bench/stage_gpu_run.sh "$BUILD"
for f in gpu_check.sh gpu_steps.sh decode_images.py COMMIT bin/perf_bench_gpu bin/gpu_parity_test bin/libtbb.so.12 lego/bench.json; do
  expect "staged $f" test -s "$STAGE/$f"
done
expect "staged PNGs" test "$(find "$STAGE/lego/images" -name '*.png' | wc -l)" -ge 100

"$BUILD/perf_bench_prep" --workspace "${WS:-.data/lego_ws}" --out "$STAGE/lego" --write-u8 > "$TMP/prep.log"
"$STAGE/bin/perf_bench_gpu" --data "$STAGE/lego" --check-data > "$TMP/check_data.log"
cat "$TMP/check_data.log"
expect "--check-data builds 4 levels of rays" test "$(grep -c '^level [0-3]: ' "$TMP/check_data.log")" -eq 4

set +e
OUT=$TMP/out BUDGET=300 bash "$STAGE/gpu_check.sh" > "$TMP/check.log" 2>&1
rc=$?
set -e
cat "$TMP/check.log"
S=$TMP/out/summary.txt
expect "gpu_check.sh exits non-zero" test "$rc" -ne 0
expect "verdict FAIL" grep -q '^RESULT: FAIL$' "$S"
expect "parity ran with gtest XML" test -s "$TMP/out/parity.xml"
expect "parity cases failed, none skipped" grep -Eq '^parity +[0-9]+ tests, [1-9][0-9]* failed, 0 errors, 0 skipped' "$S"
expect "the failure says PERF_REQUIRE_GPU and why" grep -q 'no CUDA device: .*PERF_REQUIRE_GPU is set' "$TMP/out/parity.log"
expect "the benchmark says no CUDA device" grep -q 'no CUDA device' "$TMP/out/gn128.log"
expect "every step is in the summary" grep -q '^both256 ' "$S"
echo "dry run: $(($(date +%s) - t0)) s, $problems problem(s)"
[ "$problems" -eq 0 ]
