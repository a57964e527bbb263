#!/usr/bin/env bash
# Dry run of perf on a GPU machine (stage_perf_gpu.sh + perf_gpu_run.sh, issue 61) on a machine
# without a GPU, on the example shipped in examples/bonsai_mini (imported at full size, 200x133):
#   1. stages into a temporary folder (which runs the staging's own checks: libraries, glibc
#      versions, size) and checks what is there;
#   2. runs the staged perf_gpu_run.sh as on the device (DEVICE=cuda): it must end RESULT: FAIL,
#      perf_gpu saying there is no CUDA device (a failure, not a skip), and the script's exit
#      status non-zero;
#   3. runs it with DEVICE=cpu and the one-level "smoke" configuration: every step after the
#      device's must succeed (reconstruct, the held-out renders with their scores, a 1-bit mask of
#      every photo, the run's summary line), so that the GPU run's steps are known to work.
# Exit 77 (a skip for CTest) where a GPU is visible: run the staged script itself there.
#   usage: bench/perf_gpu_dry_run.sh BUILD_DIR     (a CUDA build with perf and perf_gpu built;
#          PYTHON: a python3 with numpy and Pillow, default /usr/bin/python3)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=$(cd "${1:?usage: bench/perf_gpu_dry_run.sh BUILD_DIR}" && pwd)
source bench/dry_run_lib.sh  # skips where a GPU is; TMP, expect, problems
PYTHON=${PYTHON:-/usr/bin/python3}
STAGE=$TMP/perf_gpu_run

t0=$(date +%s)
COLMAP=examples/bonsai_mini/sparse/0 IMAGES=examples/bonsai_mini/images WS=$TMP/ws STAGE=$STAGE PACK=$TMP/pack \
  bench/stage_perf_gpu.sh "$BUILD"
for f in perf_gpu_run.sh gpu_steps.sh masks_from_opacity.py COMMIT bin/perf_gpu bin/libtbb.so.12 ws/scene.json; do
  expect "staged $f" test -s "$STAGE/$f"
done
photos=$(find "$STAGE/ws/images" -name '*.png' | wc -l)
expect "staged the workspace's photos ($photos)" test "$photos" -ge 30
expect "packed" test -s "$TMP/pack/perf_gpu_run.tgz"

# 2. As on the device, without one.
set +e
OUT=$TMP/out_cuda BUDGET=120 RUNS=smoke PYTHON=$PYTHON bash "$STAGE/perf_gpu_run.sh" > "$TMP/cuda.log" 2>&1
status=$?
set -e
cat "$TMP/out_cuda/summary.txt"
expect "the device run exits non-zero" test "$status" -ne 0
expect "its verdict is FAIL" grep -q '^RESULT: FAIL' "$TMP/out_cuda/summary.txt"
expect "perf_gpu says there is no CUDA device" grep -q 'no CUDA device' "$TMP/out_cuda/recon_smoke.log"
expect "the reconstruct failure is in the summary" grep -q 'FAIL: recon_smoke exit status' "$TMP/out_cuda/summary.txt"

# 3. Every step on the CPU.
set +e
OUT=$TMP/out_cpu BUDGET=300 RUNS=smoke DEVICE=cpu PYTHON=$PYTHON bash "$STAGE/perf_gpu_run.sh" > "$TMP/cpu.log" 2>&1
set -e
cat "$TMP/out_cpu/summary.txt"
for s in recon_smoke test_smoke masks_smoke; do
  expect "$s succeeded on the CPU" grep -qE "^$s +rc=0 " "$TMP/out_cpu/summary.txt"
done
expect "the run's line names its level and score" grep -qE '^smoke +1 of 1 levels .*held-out [0-9.]+ dB' "$TMP/out_cpu/summary.txt"
expect "recon.json came back" test -s "$TMP/out_cpu/smoke/recon.json"
expect "the held-out views were scored" grep -q 'mean PSNR' "$TMP/out_cpu/test_smoke.log"
held_out=$(find "$TMP/out_cpu/smoke/test" -name '*_opacity.png' | wc -l)
expect "held-out renders with their opacity ($held_out)" test "$held_out" -ge 3
masks=$(find "$TMP/out_cpu/smoke/masks" -name '*.png' | wc -l)
all=$("$PYTHON" -c "import json,sys; print(len(json.load(open(sys.argv[1]))['images']))" "$STAGE/ws/scene.json")
expect "a mask of every photo ($masks of $all)" test "$masks" -eq "$all"
mode=$("$PYTHON" -c "import sys; from PIL import Image; print(Image.open(sys.argv[1]).mode)" \
  "$(find "$TMP/out_cpu/smoke/masks" -name '*.png' | head -n 1)")
expect "the masks are 1-bit ($mode)" test "$mode" = "1"
echo "dry run: $(($(date +%s) - t0)) s, $problems problem(s)"
[ "$problems" -eq 0 ]
