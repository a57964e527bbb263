#!/usr/bin/env bash
# Stages `perf_gpu reconstruct` / `perf_gpu render` of a real capture for a bare GPU machine
# (issue 61; bench/README.md "perf on a GPU machine") into .data/perf_gpu_run (ignored by git):
#   bin/perf_gpu            static CUDA runtime, libpng, zlib and C++ runtime; glibc >= 2.35
#   bin/libtbb.so.12        the CPU backend's threads (Debian's; loaded through perf_gpu's rpath)
#   ws/                     the capture imported here by perf at full photo size: scene.json,
#                           inputs.json, images/*.png (alpha/ where the photos had it)
#   perf_gpu_run.sh, masks_from_opacity.py   what runs there, and its mask thresholding
#   COMMIT                  the commit perf_gpu was built from
# It then checks what it staged (every library a binary needs is glibc's, libstdc++/libgcc or
# staged in bin/; no binary asks for a glibc past 2.35; the packed folder and the checkout fit the
# 64 MiB that may be carried) and fails otherwise, and packs .data/perf_gpu_pack/perf_gpu_run.tgz.
# Usage: bench/stage_perf_gpu.sh [BUILD_DIR]    (default build; a build with CUDA, perf and perf_gpu)
#   COLMAP=model folder (default ../shared/data/bonsai/sparse/0), IMAGES=its photos (default
#   ../shared/data/bonsai/images), WS=import workspace (default .data/bonsai_full, imported if it
#   has no scene.json), STAGE=folder (default .data/perf_gpu_run), PACK=folder (default beside it).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build}
COLMAP=${COLMAP:-../shared/data/bonsai/sparse/0}
IMAGES=${IMAGES:-../shared/data/bonsai/images}
WS=${WS:-.data/bonsai_full}
STAGE=${STAGE:-.data/perf_gpu_run}
PACK=${PACK:-$(dirname "$STAGE")/perf_gpu_pack}
for f in perf perf_gpu; do
  [ -x "$BUILD/$f" ] || { echo "stage_perf_gpu.sh: $BUILD/$f not built (cmake --build $BUILD --target perf perf_gpu; perf_gpu needs nvcc and libpng-dev)" >&2; exit 2; }
done
if [ ! -f "$WS/scene.json" ]; then
  [ -d "$COLMAP" ] || { echo "stage_perf_gpu.sh: no COLMAP model at $COLMAP (set COLMAP and IMAGES, or WS to an imported workspace)" >&2; exit 2; }
  "$BUILD/perf" import --colmap "$COLMAP" --images "$IMAGES" -w "$WS" -q
fi
rm -rf "$STAGE"
mkdir -p "$STAGE/bin" "$STAGE/ws"
cp "$BUILD/perf_gpu" "$STAGE/bin/"
strip "$STAGE/bin/perf_gpu"
cp -L "$(ldd "$BUILD/perf_gpu" | awk '/libtbb/ {print $3}')" "$STAGE/bin/"
# The workspace as import left it (a fit made here is not sent: the GPU fits from the start).
for f in scene.json inputs.json images alpha; do
  [ -e "$WS/$f" ] && cp -r "$WS/$f" "$STAGE/ws/"
done
[ -f "$STAGE/ws/scene.json" ] || { echo "stage_perf_gpu.sh: $WS has no scene.json" >&2; exit 2; }
cp bench/perf_gpu_run.sh bench/gpu_steps.sh bench/masks_from_opacity.py "$STAGE/"
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- recon_cuda workspace pipeline bench || commit="$commit+dirty"
echo "$commit" > "$STAGE/COMMIT"

mib=$(bench/pack_staged.sh "$STAGE" "$PACK" perf_gpu_run)
echo "staged $STAGE ($(ls "$STAGE/ws/images" | wc -l) photos), packed $PACK/perf_gpu_run.tgz ($mib MiB, commit $commit); carry $PACK, and there:"
echo "  tar xzf $PACK/perf_gpu_run.tgz -C $(dirname "$STAGE") && OUT=/tmp/pg bash $STAGE/perf_gpu_run.sh; tar czf \$OUT/perf_gpu_run_out.tgz -C /tmp/pg ."
