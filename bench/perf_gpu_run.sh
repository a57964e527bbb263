#!/usr/bin/env bash
# perf on a GPU machine (issue 61), staged by bench/stage_perf_gpu.sh: the imported capture (ws/)
# fitted by perf_gpu reconstruct on the device under each configuration of RUNS, then its
# held-out views rendered and scored (perf_gpu render) and every photo's mask thresholded from its
# box opacity; everything under $OUT, in the order:
#   device            nvidia-smi                                          -> device.log
#   recon_<run>       perf_gpu reconstruct ws_<run> --device cuda ARGS    -> recon_<run>.log, <run>/recon.json,
#                     (a copy of ws per run; device memory sampled          log.jsonl, settings.json, scene.json,
#                     every 200 ms)                                          <run>/gpu_memory.log
#   test_<run>        perf_gpu render --split test --opacity               -> <run>/test/*.png (PSNR in test_<run>.log)
#   masks_<run>       perf_gpu render --split all --opacity, then masks_from_opacity.py (0.7)
#                                                                          -> <run>/masks/<photo>.png (1-bit)
# RUNS: the configurations, each a name and the reconstruct options of recon_args() below;
# default "default high" (the GPU's default and high presets under trial: levels from the photos
# up to 256^3 and 512^3). Each reconstruct stops itself at an iteration (SIGINT) at its cap
# and keeps the levels it finished, which the renders then use.
# summary.txt: one line per step, per run the levels reached, held-out PSNR, seconds and peak
# device memory, and RESULT: PASS only if the device answered and the first run's reconstruct
# and renders succeeded. The script's exit status is 0 only then. At most BUDGET seconds (560).
#   usage: bash .data/perf_gpu_run/perf_gpu_run.sh     (OUT=folder, default ./perf_gpu_out; BUDGET=s;
#          RUNS="name ..."; DEVICE=cuda, or cpu for a dry run of the steps; PYTHON=a python3 with
#          numpy and Pillow)
set -u
HERE=$(cd "$(dirname "$0")" && pwd)
OUT=${OUT:-$PWD/perf_gpu_out}
BUDGET=${BUDGET:-560}
RUNS=${RUNS:-default high}
DEVICE=${DEVICE:-cuda}
PYTHON=${PYTHON:-python3}  # with numpy and Pillow
export PATH="$PATH:/usr/local/cuda/bin"
source "$HERE/gpu_steps.sh"  # $SUMMARY, $START, $COMMIT, left, step, fail, $verdict

# The reconstruct options of a run: the `perf run` presets' (30 iterations a level, each ending
# once its cost flattens; view-dependent colour, the cameras refined and each photo's exposure
# solved, as for COLMAP photos by default) at the photos' full size, with the GPU's finest grid.
recon_args() {
  case "$1" in
    default) echo "--iterations 30 --max-resolution 256 --sh-from-level 2" ;;
    high) echo "--iterations 30 --max-resolution 512 --sh-from-level 0" ;;
    # The dry run's (perf_gpu_dry_run.sh): one small level, on any device.
    smoke) echo "--levels 1 --iterations 1 --start-resolution 16 --no-grow-box" ;;
    *) echo "perf_gpu_run.sh: unknown run $1 (default, high, smoke)" >&2; return 1 ;;
  esac
}
# The seconds a run's reconstruct may take: the first half of what is left for the first of two
# runs (a minute kept for each run's renders), all of it for the last.
recon_cap() {
  local runs_left=$1
  local l=$(($(left) - 60 * runs_left))
  echo $((runs_left > 1 ? l / runs_left : l))
}

echo "commit $COMMIT, budget $BUDGET s, runs: $RUNS, results in $OUT" | tee -a "$SUMMARY"
step device 30 bash -c 'nvidia-smi; echo; nvidia-smi --query-gpu=name,driver_version,memory.total,compute_cap --format=csv'
[ "$STEP_RC" -eq 0 ] || fail "nvidia-smi (is there a driver?)"
"$HERE/bin/perf_gpu" --version | tee -a "$SUMMARY"

first=1
set -- $RUNS
while [ $# -gt 0 ]; do
  run=$1
  shift
  args=$(recon_args "$run") || { fail "run $run"; continue; }
  ws=$HERE/ws_$run
  rm -rf "$ws"
  cp -r "$HERE/ws" "$ws"
  mkdir -p "$OUT/$run"
  nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 200 > "$OUT/$run/gpu_memory.log" 2>/dev/null &
  sampler=$!
  # shellcheck disable=SC2086
  STEP_SIGNAL=INT step "recon_$run" "$(recon_cap $(($# + 1)))" "$HERE/bin/perf_gpu" reconstruct "$ws" --device "$DEVICE" $args
  rc=$STEP_RC
  kill "$sampler" 2>/dev/null
  for f in recon.json log.jsonl settings.json; do [ -f "$ws/recon/$f" ] && cp "$ws/recon/$f" "$OUT/$run/"; done
  cp "$ws/scene.json" "$OUT/$run/"
  # rc 130: stopped at its cap after finishing some levels (kept); anything else but 0 failed.
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 130 ]; then
    [ "$first" -eq 1 ] && fail "recon_$run exit status $rc (recon_$run.log)"
  fi
  if ls "$ws"/recon/level_*.perfvol > /dev/null 2>&1; then
    step "test_$run" 120 "$HERE/bin/perf_gpu" render "$ws" --device "$DEVICE" --split test --opacity -o "$OUT/$run/test"
    [ "$STEP_RC" -eq 0 ] || { [ "$first" -eq 1 ] && fail "test_$run exit status $STEP_RC"; }
    step "masks_$run" 120 bash -c "'$HERE/bin/perf_gpu' render '$ws' --device $DEVICE --split all --opacity -o '$ws/all' -q && '$PYTHON' '$HERE/masks_from_opacity.py' '$ws/all' '$OUT/$run/masks'"
    [ "$STEP_RC" -eq 0 ] || { [ "$first" -eq 1 ] && fail "masks_$run exit status $STEP_RC"; }
  else
    [ "$first" -eq 1 ] && fail "recon_$run finished no level"
  fi
  "$PYTHON" - "$OUT/$run" "$run" <<'PY' | tee -a "$SUMMARY"
import json, os, sys
d, run = sys.argv[1], sys.argv[2]
line = f"{run:9s}"
try:
    r = json.load(open(os.path.join(d, "recon.json")))
    runs = r.get("levels_run", [])
    line += f" {len(runs)} of {r.get('levels')} levels"
    if runs:
        last = runs[-1]
        line += f" (last {last['n']}^3, {last['iterations']} iterations, images / {last['image_downscale']})"
    line += f", held-out {r.get('test_psnr', 0):.2f} dB, solve {r.get('solve_seconds', 0):.1f} s, {r.get('backend')}"
    if r.get("memory_stop"):
        line += f", memory stop: {r['memory_stop']}"
except (OSError, ValueError, KeyError):
    # Stopped at its cap: the levels it finished, from log.jsonl.
    levels = []
    try:
        for text in open(os.path.join(d, "log.jsonl")):
            j = json.loads(text)
            if j.get("event") == "level":
                levels.append(j)
    except (OSError, ValueError):
        pass
    line += f" stopped after {len(levels)} levels (no recon.json)"
    if levels:
        last = levels[-1]
        line += f", last {last['n']}^3 held-out {last.get('test_psnr', 0):.2f} dB at {last.get('elapsed', 0):.1f} s"
try:
    mib = [int(x) for x in open(os.path.join(d, "gpu_memory.log")).read().split() if x.isdigit()]
    if mib:
        line += f", peak device memory {max(mib)} MiB"
except OSError:
    pass
print(line)
PY
  first=0
done

echo "total $(($(date +%s) - START)) s of $BUDGET s" | tee -a "$SUMMARY"
echo "RESULT: $verdict" | tee -a "$SUMMARY"
[ "$verdict" = PASS ]
