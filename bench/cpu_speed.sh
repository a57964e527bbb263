#!/usr/bin/env bash
# CPU time to quality, the commit before issue 33's work against a newer one, back to back on this
# machine (issue 33; docs/tuning.md "CPU speed"). Builds both commits (CPU only, `perf` and
# `perf_bench_cpu`) in git worktrees under .data/speed/, runs each scenario on each build in turn
# and prints the ratios; the JSON of every run goes to $OUT/cpu_speed.json.
#
#   bench/cpu_speed.sh [SCENARIO ...]      scenarios: lego200 lego200sh sh lego50 passes bonsai (default: lego200 sh passes)
#
# Environment: BASE (default da0c75a, the last commit before issue 33's work), NEW (default HEAD),
# NEW_ARGS (extra `perf reconstruct`/`perf run` options for the new build, e.g. "--jtj-ray-stride 1"
# to switch a new default off), DATA (default ../shared/data), OUT (default .data/speed/out),
# TOL (dB below the base's final held-out PSNR that counts as reached; default 0.05).
#
#   lego200  lego 200x200 (--downscale 4), 4 levels to 256^3, 4,4,4,8 iterations, 12 CG, held-out
#            PSNR after every iteration: solver seconds to reach the base's final PSNR - TOL
#   lego200sh  lego200, then a third run: the new build with --sh-degree 1 (bands at 256^3, in place
#            of any --sh-degree in NEW_ARGS), the base's final PSNR - TOL reached with view
#            dependence against without (a new build from stop 57 on: NEW_ARGS="--sh-degree 0")
#   lego50   the same at 50x50 (--downscale 16), 3 levels, 8 iterations each: a quick check
#   sh       lego 50x50, --sh-degree 0 against 1 on each build: the ratio of solver seconds
#   passes   perf_bench_cpu on the new build's lego200 128^3 checkpoint: samples/s of the sparse
#            passes against the same volume dense (--as-dense), each build
#   bonsai   ../shared/data/bonsai as each build's `perf run --preset default` runs it (import at 400 px, then
#            each build's reconstruct with held-out PSNR after every iteration, export and eval;
#            about 45 min for the base, 25 for the new): time to the base's final PSNR - TOL,
#            held-out and in-mask PSNR of eval, peak resident memory of the stages (/usr/bin/time)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
BASE=${BASE:-da0c75a}
NEW=${NEW:-HEAD}
DATA=${DATA:-$ROOT/../shared/data}
OUT=${OUT:-$ROOT/.data/speed/out}
TOL=${TOL:-0.05}
NEW_ARGS=${NEW_ARGS:-}
SCENARIOS=("$@")
[ ${#SCENARIOS[@]} -gt 0 ] || SCENARIOS=(lego200 sh passes)
for s in "${SCENARIOS[@]}"; do
  case $s in lego200|lego200sh|lego50|sh|passes|bonsai) ;;
    *) echo "cpu_speed.sh: unknown scenario '$s' (lego200 lego200sh lego50 sh passes bonsai)" >&2; exit 2;; esac
done
[ -d "$DATA/lego" ] || { echo "cpu_speed.sh: $DATA/lego not found (set DATA to the shared data folder)" >&2; exit 2; }
export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(dirname "$ROOT")}
mkdir -p "$OUT"

# build REF -> prints the build folder holding perf and perf_bench_cpu
build() {
  local sha dir
  sha=$(git rev-parse --short=10 "$1^{commit}")
  dir=$ROOT/.data/speed/src-$sha
  [ -d "$dir" ] || git worktree add --detach "$dir" "$sha" >&2
  if [ ! -f "$dir/build/build.ninja" ]; then
    cmake -S "$dir" -B "$dir/build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPERF_ENABLE_CUDA=OFF -DPERF_ENABLE_MPI=OFF >&2
  fi
  cmake --build "$dir/build" -j "$(nproc)" --target perf perf_bench_cpu >&2
  echo "$dir/build"
}

echo "== building $BASE and $NEW (CPU only)"
B_BASE=$(build "$BASE")
B_NEW=$(build "$NEW")
echo "base: $(git rev-parse --short "$BASE") $B_BASE"
echo "new:  $(git rev-parse --short "$NEW") $B_NEW ${NEW_ARGS:+(with $NEW_ARGS)}"
echo "machine: $(nproc) cores, $(awk '/MemTotal/ {printf "%.0f GiB", $2 / 1048576}' /proc/meminfo), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"

# import NAME ARGS...: a workspace made once, by the new build, shared by every run (copied)
import() {
  local name=$1
  shift
  [ -f "$OUT/$name/scene.json" ] || "$B_NEW/perf" import -q -w "$OUT/$name" "$@"
}

# fresh NAME -> a copy of the imported workspace without a previous run's outputs
fresh() {
  rm -rf "$OUT/run_$1"
  mkdir -p "$OUT/run_$1"
  cp -a "$OUT/$1/scene.json" "$OUT/$1/inputs.json" "$OUT/$1/images" "$OUT/run_$1/"
  [ -d "$OUT/$1/alpha" ] && cp -a "$OUT/$1/alpha" "$OUT/run_$1/"
  echo "$OUT/run_$1"
}

# reconstruct TAG BUILD WS ARGS...: perf reconstruct, its log kept as $OUT/TAG.log.jsonl, peak RSS in $OUT/TAG.time
reconstruct() {
  local tag=$1 build=$2 ws=$3
  shift 3
  /usr/bin/time -v -o "$OUT/$tag.time" "$build/perf" reconstruct "$ws" -q "$@"
  cp "$ws/recon/log.jsonl" "$OUT/$tag.log.jsonl"
}

# side SIDE: the build (b) and the extra options (extra) of side base or new
side() {
  b=$B_BASE
  extra=()
  if [ "$1" = new ]; then b=$B_NEW; extra=($NEW_ARGS); fi
}

summary() {  # summary TAG...: time to quality and peaks from the kept logs
  python3 "$ROOT/bench/cpu_speed_summary.py" --out "$OUT" --tol "$TOL" "$@"
}

for s in "${SCENARIOS[@]}"; do
  case $s in
    lego200|lego200sh|lego50)
      with_sh=false
      [ "$s" = lego200sh ] && { s=lego200; with_sh=true; }
      if [ "$s" = lego200 ]; then
        import lego200 --nerf "$DATA/lego/transforms_train.json" --downscale 4
        args=(--levels 4 --level-iterations 4,4,4,8 --max-cg-iterations 12 --eval-every 1)
      else
        import lego50 --nerf "$DATA/lego/transforms_train.json" --downscale 16
        args=(--levels 3 --iterations 8 --eval-every 1)
      fi
      ws=$(fresh "$s")
      echo "== $s base"; reconstruct "$s-base" "$B_BASE" "$ws" "${args[@]}"
      ws=$(fresh "$s")
      echo "== $s new"; reconstruct "$s-new" "$B_NEW" "$ws" "${args[@]}" $NEW_ARGS
      [ "$s" = lego200 ] && { rm -rf "$OUT/lego200-new-recon"; cp -a "$ws/recon" "$OUT/lego200-new-recon"; }
      summary --pair "$s-base" "$s-new"
      if $with_sh; then
        ws=$(fresh "$s")
        echo "== $s new --sh-degree 1"; reconstruct "$s-newsh" "$B_NEW" "$ws" "${args[@]}" $(sed -E 's/--sh-degree[ =]?[0-9]//' <<< "$NEW_ARGS") --sh-degree 1
        summary --pair "$s-base" "$s-newsh"
      fi
      ;;
    sh)
      import lego50 --nerf "$DATA/lego/transforms_train.json" --downscale 16
      for side in base new; do
        side $side
        for d in 0 1; do
          ws=$(fresh lego50)
          echo "== sh $side degree $d"; reconstruct "sh$d-$side" "$b" "$ws" --levels 2 --iterations 8 --sh-degree $d "${extra[@]}"
        done
      done
      summary --sh
      ;;
    passes)
      ck=$OUT/lego200-new-recon/level_2.perfvol
      [ -f "$ck" ] || { echo "passes: run lego200 first (needs $ck)" >&2; exit 2; }
      for side in base new; do
        side $side
        for mode in sparse dense; do
          flag=(); [ $mode = dense ] && flag=(--as-dense)
          echo "== passes $side $mode"
          "$b/perf_bench_cpu" --workspace "$OUT/lego200" --checkpoint "$ck" --n 128 --repeat 1 "${flag[@]}" \
            --json "$OUT/passes-$side-$mode.json" | tail -n 4
        done
      done
      summary --passes
      ;;
    bonsai)
      [ -d "$DATA/bonsai" ] || { echo "bonsai: $DATA/bonsai not found" >&2; exit 2; }
      # perf run --preset default's stages one by one, so that the solve logs the held-out PSNR
      # after every iteration: its import (once, by the new build), then each build's reconstruct
      # (the preset's settings: perf reconstruct's defaults, and since ee2268c the new build's
      # view-dependent colour from level 2; the base's preset had none),
      # export and eval. Peak: the largest of the three stages'.
      import bonsai --colmap "$DATA/bonsai/sparse/0" --images "$DATA/bonsai/images" --max-size 400
      for side in base new; do
        side $side
        ws=$(fresh bonsai)
        echo "== bonsai $side"
        preset=()
        [ $side = new ] && [[ " $NEW_ARGS " != *" --sh-"* ]] && preset=(--sh-degree 1 --sh-from-level 2)
        reconstruct "bonsai-$side" "$b" "$ws" --eval-every 1 "${preset[@]}" "${extra[@]}"
        for stage in export eval; do
          /usr/bin/time -v -o "$OUT/bonsai-$side.$stage.time" "$b/perf" $stage "$ws" -q
        done
        cp "$ws/report.json" "$OUT/bonsai-$side.report.json"
      done
      summary --pair bonsai-base bonsai-new
      ;;
  esac
done
summary --json "$OUT/cpu_speed.json"
