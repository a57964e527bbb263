#!/usr/bin/env bash
# Builds libFuzzer targets with AddressSanitizer and UBSan, seeds each from real inputs, and
# fuzzes for a while:
#   colmap_bin  the COLMAP model readers      (fuzz/colmap_bin_fuzzer.cc; seeds: bonsai's model)
#   checkpoint  the checkpoint reader         (fuzz/checkpoint_fuzzer.cc; seeds: written checkpoints)
#   nerf_json   the NeRF transforms.json one  (fuzz/nerf_json_fuzzer.cc; seeds: lego's json, cut)
#
# Usage: scripts/fuzz.sh [TARGET] [SECONDS]   TARGET: colmap_bin, checkpoint, nerf_json or all
#                                             (default all); SECONDS per target (default 60).
#        scripts/fuzz.sh SECONDS              as before: colmap_bin alone.
# Output in build-fuzz/<target>/: the corpus grows in corpus/ across runs; a crashing, leaking,
# hanging or over-allocating input lands in crashes/ and the script exits non-zero. Reproduce
# one with
#   build-fuzz/<target>_fuzzer build-fuzz/<target>/crashes/<file>
# and keep it as a regression input in fuzz/regressions/<target>/ (the unit tests read them).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
if [[ ${1:-} =~ ^[0-9]+$ ]]; then
  target=colmap_bin seconds=$1
else
  target=${1:-all} seconds=${2:-60}
fi
out=$root/build-fuzz
cxx=${CXX:-clang++}
data=${PERF_SHARED_DATA_DIR:-$root/../shared/data}

# Per target: the sources besides the fuzzer (only what the reader needs: no generated headers,
# no CMake), extra compiler flags, the seed maker's arguments and the largest input.
declare -A srcs=(
  [colmap_bin]="sfm_import/colmap_model.cc sfm_import/colmap_model_binary.cc sfm_import/colmap_model_text.cc sfm_import/camera_models.cc common/errors.cc common/atomic_file.cc common/inputs.cc common/owned_files.cc"
  [checkpoint]="recon_cuda/data/checkpoint.cc recon_cuda/data/brick_grid.cc common/errors.cc common/atomic_file.cc common/inputs.cc common/owned_files.cc"
  [nerf_json]="sfm_import/nerf_reader.cc workspace/image_io.cc workspace/image_ops.cc common/errors.cc common/atomic_file.cc common/inputs.cc common/owned_files.cc common/system_memory.cc"
)
declare -A flags=(
  [colmap_bin]=""
  [checkpoint]=""
  [nerf_json]="-I/usr/include/eigen3 -lOpenImageIO -lOpenImageIO_Util"
)
declare -A seed_args=(
  [colmap_bin]="$data/bonsai/sparse/0"
  [checkpoint]=""
  [nerf_json]="$data/lego/transforms_train.json"
)
declare -A max_len=([colmap_bin]=16384 [checkpoint]=16384 [nerf_json]=16384)

case $target in
  all) targets=(colmap_bin checkpoint nerf_json) ;;
  colmap_bin | checkpoint | nerf_json) targets=("$target") ;;
  *) echo "unknown target '$target': use colmap_bin, checkpoint, nerf_json or all" >&2; exit 2 ;;
esac

cd "$root"
for t in "${targets[@]}"; do
  dir=$out/$t
  mkdir -p "$dir/corpus" "$dir/seeds" "$dir/crashes"
  # shellcheck disable=SC2206  # the lists above are space-separated on purpose
  files=(${srcs[$t]}) extra=(${flags[$t]})

  echo "== building $out/${t}_fuzzer"
  # -fno-sanitize-recover: UBSan findings abort, so libFuzzer records them as crashes.
  "$cxx" -std=c++20 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
    -I"$root" "fuzz/${t}_fuzzer.cc" "${files[@]}" "${extra[@]}" -o "$out/${t}_fuzzer"
  "$cxx" -std=c++20 -g -O1 -DPERF_FUZZ_MAKE_SEEDS -I"$root" "fuzz/${t}_fuzzer.cc" "${files[@]}" "${extra[@]}" \
    -o "$out/${t}_make_seeds"

  echo "== seeding $dir/seeds (${seed_args[$t]:-built in})"
  # shellcheck disable=SC2086  # an empty argument list stays empty
  "$out/${t}_make_seeds" "$dir/seeds" ${seed_args[$t]}
  ls "$dir/seeds" | tr '\n' ' '
  echo

  echo "== fuzzing $t for ${seconds}s"
  # -timeout: an input taking 10 s is a hang; -rss_limit_mb / -malloc_limit_mb: a reader must
  # not allocate far beyond the input size (max_len), so a single 1 GiB allocation is a finding.
  regressions=()
  [[ -d fuzz/regressions/$t ]] && regressions=("fuzz/regressions/$t")
  "$out/${t}_fuzzer" -max_total_time="$seconds" -max_len="${max_len[$t]}" -timeout=10 \
    -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 -artifact_prefix="$dir/crashes/" \
    "$dir/corpus" "$dir/seeds" "${regressions[@]}"
done
