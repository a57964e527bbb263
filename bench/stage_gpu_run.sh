#!/usr/bin/env bash
# Stages what a bare GPU machine needs for bench/gpu_check.sh (the gpu tests, compute-sanitizer
# and the GPU benchmark) into .data/gpu_run (ignored by git), from a build made here
# (bench/README.md):
#   gpu_check.sh, decode_images.py   the script the GPU machine runs, and its PNG decoder
#   bin/perf_bench_gpu      static CUDA runtime and libstdc++; needs glibc >= 2.35 only
#   bin/gpu_parity_test     plus bin/libtbb.so.12 (the CPU backend it compares against)
#   lego/bench.json         cameras, split, box and shells (perf_bench_prep)
#   lego/images/*.png       the workspace's RGB and alpha PNGs (~39 MB; decoded there by decode_images.py)
#   COMMIT                  the commit the binaries were built from
# It then checks and packs what it staged (pack_staged.sh: every library the binaries need is
# glibc's, libstdc++/libgcc or staged in bin/, no binary asks for a glibc newer than 2.35, and the
# pack and the checkout fit the 64 MiB that may be carried to the GPU machine).
# Usage: bench/stage_gpu_run.sh [BUILD_DIR]   (default build-cuda; LEGO=path/to/lego,
#        STAGE=folder (default .data/gpu_run), WS=import workspace (default .data/lego_ws))
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build-cuda}
LEGO=${LEGO:-../shared/data/lego}
WS=${WS:-.data/lego_ws}
STAGE=${STAGE:-.data/gpu_run}
for f in perf_bench_gpu perf_bench_prep tests/gpu_parity_test; do
  [ -x "$BUILD/$f" ] || { echo "stage_gpu_run.sh: $BUILD/$f not built (cmake --build $BUILD --target perf perf_bench_prep perf_bench_gpu gpu_parity_test)" >&2; exit 2; }
done
if [ ! -f "$WS/scene.json" ]; then
  # 87 training views, every 8th of the 100 held out (r_0, r_8, ...), composited over white.
  "$BUILD/perf" import --nerf "$LEGO/transforms_train.json" -w "$WS" --holdout 8 -q
fi
rm -rf "$STAGE"
mkdir -p "$STAGE/bin"
"$BUILD/perf_bench_prep" --workspace "$WS" --out "$STAGE/lego"
cp "$BUILD/perf_bench_gpu" "$BUILD/tests/gpu_parity_test" "$STAGE/bin/"
strip "$STAGE/bin/perf_bench_gpu" "$STAGE/bin/gpu_parity_test"  # symbols: ~1.5 MB of the 64 MiB
cp -L "$(ldd "$BUILD/tests/gpu_parity_test" | awk '/libtbb/ {print $3}')" "$STAGE/bin/"
cp bench/gpu_check.sh bench/gpu_steps.sh bench/decode_images.py "$STAGE/"
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- recon_cuda bench tests/recon || commit="$commit+dirty"
echo "$commit" > "$STAGE/COMMIT"

PACK=${PACK:-$(dirname "$STAGE")/gpu_pack}
mib=$(bench/pack_staged.sh "$STAGE" "$PACK" gpu_run)
echo "staged $STAGE, packed $PACK/gpu_run.tgz ($mib MiB, commit $commit); carry $PACK, and there:"
echo "  tar xzf $PACK/gpu_run.tgz -C $(dirname "$STAGE") && OUT=/tmp/gc bash $STAGE/gpu_check.sh; tar czf \$OUT/gpu_check.tgz -C /tmp/gc ."

