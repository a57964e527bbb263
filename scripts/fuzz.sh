#!/usr/bin/env bash
# Builds the libFuzzer target for the COLMAP model readers (fuzz/colmap_bin_fuzzer.cc) with
# AddressSanitizer and UBSan, seeds a corpus, and fuzzes for a while.
#
# Usage: scripts/fuzz.sh [SECONDS]     (default 60)
# Output in build-fuzz/: the corpus grows in corpus/ across runs; a crashing, leaking or
# hanging input lands in crashes/ and the script exits non-zero. Reproduce one with
#   build-fuzz/colmap_bin_fuzzer build-fuzz/crashes/<file>
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
seconds=${1:-60}
out=$root/build-fuzz
cxx=${CXX:-clang++}
# Only what the readers need (no generated headers, no CMake).
srcs=(sfm_import/colmap_model.cc sfm_import/camera_models.cc common/errors.cc common/atomic_file.cc)
bonsai=${PERF_SHARED_DATA_DIR:-$root/../shared/data}/bonsai/sparse/0

mkdir -p "$out/corpus" "$out/seeds" "$out/crashes"
cd "$root"

echo "== building $out/colmap_bin_fuzzer"
# -fno-sanitize-recover: UBSan findings abort, so libFuzzer records them as crashes.
"$cxx" -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
  -I"$root" fuzz/colmap_bin_fuzzer.cc "${srcs[@]}" -o "$out/colmap_bin_fuzzer"
"$cxx" -std=c++20 -g -O1 -DPERF_FUZZ_MAKE_SEEDS -I"$root" fuzz/colmap_bin_fuzzer.cc "${srcs[@]}" \
  -o "$out/make_seeds"

echo "== seeding $out/seeds (bonsai: $bonsai)"
"$out/make_seeds" "$out/seeds" "$bonsai"
ls "$out/seeds" | tr '\n' ' '
echo

echo "== fuzzing for ${seconds}s"
# -timeout: an input taking 10 s is a hang; -rss_limit_mb: readers must not allocate far
# beyond the input size (max_len 16 KiB).
"$out/colmap_bin_fuzzer" -max_total_time="$seconds" -max_len=16384 -timeout=10 \
  -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$out/crashes/" \
  "$out/corpus" "$out/seeds"
