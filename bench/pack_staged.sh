#!/usr/bin/env bash
# Checks and packs a folder staged for a bare GPU machine (stage_gpu_run.sh, stage_perf_gpu.sh):
# every library the binaries in STAGE/bin need is glibc's, libstdc++/libgcc (every CUDA machine
# has them) or staged beside them; no binary asks for a symbol version of glibc past 2.35 (Ubuntu
# 22.04); then packs STAGE into PACK/NAME.tgz and checks that it and the checkout fit the 64 MiB
# that may be carried. Exit 1 naming the problem.
# Usage: bench/pack_staged.sh STAGE PACK NAME     (from the repository root)
set -euo pipefail
STAGE=$1 PACK=$2 NAME=$3
who=$(basename "$0")
bad=0
for b in "$STAGE"/bin/*; do
  while read -r lib; do
    case "$lib" in
      linux-vdso.so.*|ld-linux-x86-64.so.*|libc.so.6|libm.so.6|libdl.so.2|libpthread.so.0|librt.so.1|libgcc_s.so.1|libstdc++.so.6) ;;
      *) if [ ! -f "$STAGE/bin/$lib" ]; then echo "$who: $(basename "$b") needs $lib, which is not staged" >&2; bad=1; fi ;;
    esac
  done < <(LD_LIBRARY_PATH="$STAGE/bin" ldd "$b" | awk '{print $1}' | sed 's|.*/||')
  newest=$(objdump -T "$b" | grep -o 'GLIBC_2\.[0-9]*' | sort -t. -k2 -n -u | tail -1)
  if [ -n "$newest" ] && [ "${newest#GLIBC_2.}" -gt 35 ]; then
    echo "$who: $(basename "$b") needs $newest (the GPU machine may have glibc 2.35)" >&2
    bad=1
  fi
done
[ "$bad" -eq 0 ] || exit 1
# What travels is one gzip'd tar (the binaries' device code compresses), with the checkout under
# the 64 MiB that may be carried.
mkdir -p "$PACK"
tar czf "$PACK/$NAME.tgz.tmp" -C "$(dirname "$STAGE")" "$(basename "$STAGE")"
mv "$PACK/$NAME.tgz.tmp" "$PACK/$NAME.tgz"
kib=$(du -sk "$PACK/$NAME.tgz" | cut -f1)
tree_kib=$(git ls-files -z | xargs -0 du -ck | tail -n 1 | cut -f1)
if [ $((kib + tree_kib)) -gt $((64 * 1024)) ]; then
  echo "$who: $PACK/$NAME.tgz ($((kib / 1024)) MiB) and the checkout ($((tree_kib / 1024)) MiB) are over the 64 MiB that may be carried" >&2
  exit 1
fi
echo "$((kib / 1024))"
