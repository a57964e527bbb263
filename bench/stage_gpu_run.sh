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
# It then checks what it staged: every library the binaries need is glibc's, libstdc++/libgcc
# or staged in bin/, no binary asks for a glibc newer than 2.35, and the whole fits the 64 MiB
# that may be carried to the GPU machine.
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
cp bench/gpu_check.sh bench/decode_images.py "$STAGE/"
commit=$(git rev-parse --short HEAD)
git diff --quiet HEAD -- recon_cuda bench tests/recon || commit="$commit+dirty"
echo "$commit" > "$STAGE/COMMIT"

# What travels must load there: glibc, libstdc++ and libgcc (every CUDA machine has them), the
# libraries staged beside the binaries, and no symbol version of glibc past 2.35 (Ubuntu 22.04).
bad=0
for b in "$STAGE"/bin/*; do
  while read -r lib; do
    case "$lib" in
      linux-vdso.so.*|ld-linux-x86-64.so.*|libc.so.6|libm.so.6|libdl.so.2|libpthread.so.0|librt.so.1|libgcc_s.so.1|libstdc++.so.6) ;;
      *) if [ ! -f "$STAGE/bin/$lib" ]; then echo "stage_gpu_run.sh: $(basename "$b") needs $lib, which is not staged" >&2; bad=1; fi ;;
    esac
  done < <(LD_LIBRARY_PATH="$STAGE/bin" ldd "$b" | awk '{print $1}' | sed 's|.*/||')
  newest=$(objdump -T "$b" | grep -o 'GLIBC_2\.[0-9]*' | sort -t. -k2 -n -u | tail -1)
  if [ -n "$newest" ] && [ "${newest#GLIBC_2.}" -gt 35 ]; then
    echo "stage_gpu_run.sh: $(basename "$b") needs $newest (the GPU machine may have glibc 2.35)" >&2
    bad=1
  fi
done
[ "$bad" -eq 0 ] || exit 1
# What travels is one gzip'd tar beside the folder (the binaries' device code compresses; the
# folder itself was 66 MiB on 2026-12-04): .data/gpu_pack/gpu_run.tgz, with the checkout under
# the 64 MiB that may be carried.
PACK=${PACK:-$(dirname "$STAGE")/gpu_pack}
mkdir -p "$PACK"
tar czf "$PACK/gpu_run.tgz.tmp" -C "$(dirname "$STAGE")" "$(basename "$STAGE")"
mv "$PACK/gpu_run.tgz.tmp" "$PACK/gpu_run.tgz"
kib=$(du -sk "$PACK/gpu_run.tgz" | cut -f1)
tree_kib=$(git ls-files -z | xargs -0 du -ck | tail -n 1 | cut -f1)
if [ $((kib + tree_kib)) -gt $((64 * 1024)) ]; then
  echo "stage_gpu_run.sh: $PACK/gpu_run.tgz ($((kib / 1024)) MiB) and the checkout ($((tree_kib / 1024)) MiB) are over the 64 MiB that may be carried" >&2
  exit 1
fi
echo "staged $STAGE, packed $PACK/gpu_run.tgz ($((kib / 1024)) MiB, commit $commit); carry $PACK, and there:"
echo "  tar xzf $PACK/gpu_run.tgz -C $(dirname "$STAGE") && OUT=/tmp/gc bash $STAGE/gpu_check.sh; tar czf \$OUT/gpu_check.tgz -C /tmp/gc ."

