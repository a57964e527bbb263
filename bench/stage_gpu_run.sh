#!/usr/bin/env bash
# Stages what a bare GPU machine needs for the gpu tests and the GPU benchmark into
# .data/gpu_run (ignored by git), from a build made here (bench/README.md):
#   bin/perf_bench_gpu      static CUDA runtime and libstdc++; needs glibc >= 2.35 only
#   bin/gpu_parity_test     plus bin/libtbb.so.12 (the CPU backend it compares against)
#   lego/bench.json         cameras, split, box and shells (perf_bench_prep)
#   lego/images/*.png       the workspace's RGB and alpha PNGs (~39 MB; decoded there by decode_images.py)
#   COMMIT                  the commit the binaries were built from
# Usage: bench/stage_gpu_run.sh [BUILD_DIR]   (default build-cuda; LEGO=path/to/lego to override)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build-cuda}
LEGO=${LEGO:-../shared/data/lego}
WS=.data/lego_ws
OUT=.data/gpu_run
if [ ! -f "$WS/scene.json" ]; then
  # 87 training views, every 8th of the 100 held out (r_0, r_8, ...), composited over white.
  "$BUILD/perf" import --nerf "$LEGO/transforms_train.json" -w "$WS" --holdout 8 -q
fi
rm -rf "$OUT"
mkdir -p "$OUT/bin"
"$BUILD/perf_bench_prep" --workspace "$WS" --out "$OUT/lego"
cp "$BUILD/perf_bench_gpu" "$BUILD/tests/gpu_parity_test" "$OUT/bin/"
cp -L "$(ldd "$BUILD/tests/gpu_parity_test" | awk '/libtbb/ {print $3}')" "$OUT/bin/"
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- recon_cuda bench tests/recon || commit="$commit+dirty"
echo "$commit" > "$OUT/COMMIT"
du -sh "$OUT"
