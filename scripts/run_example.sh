#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job on the shipped example
# (examples/bonsai_mini: 42 photos of the mip-NeRF 360 bonsai with a COLMAP model).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
rm -rf out/bonsai_mini
./build/perf import --colmap examples/bonsai_mini/sparse/0 --images examples/bonsai_mini/images \
  --workspace out/bonsai_mini --preview-box
echo
echo "Workspace: out/bonsai_mini (scene.json, images/, preview/box_*.png shows the box over held-out views)"
