#!/usr/bin/env bash
# README command 1: install what is missing, build the `perf` tool, and run the whole pipeline on
# the shipped example (examples/bonsai_mini: 42 photos of the mip-NeRF 360 bonsai with their
# COLMAP model) with the preview preset: masks, cut-outs, volume, mesh, renders and a report in
# out/bonsai_mini/. Running it again skips what is up to date; Ctrl-C and re-running resumes.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if [ ! -f build/build.ninja ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release
fi
cmake --build build -j "$(nproc)" --target perf
./build/perf run --colmap examples/bonsai_mini/sparse/0 --images examples/bonsai_mini/images \
  --workspace out/bonsai_mini --preset preview "$@"
echo "Open out/bonsai_mini/report.html in a browser; the assets are listed above."
