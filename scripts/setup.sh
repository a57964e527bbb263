#!/usr/bin/env bash
# Installs every Debian 12 package PERF needs to build, test and run. Idempotent and
# non-interactive: packages already present are left alone; apt-get update runs first.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git python3
  libopenimageio-dev openimageio-tools   # image I/O and filtered resize; oiiotool for tests
  libpng-dev zlib1g-dev                  # perf_gpu's PNG I/O, linked statically (runs on bare GPU machines)
  libopencv-dev                          # undistortion, image metrics
  libeigen3-dev                          # geometry
  libceres-dev                           # derivative checks, reference solves
  libcli11-dev                           # the CLI
  nlohmann-json3-dev                     # scene.json
  libtbb-dev                             # CPU threads
  libopenvdb-dev libboost-dev libopenvdb-tools  # volume export and meshing (+ vdb_print)
  libmeshoptimizer-dev                   # mesh simplification (--mesh-triangles)
  assimp-utils                           # the independent check of the mesh files (MeshAssimpTest)
  libgtest-dev libgmock-dev libbenchmark-dev    # tests and benchmarks
  colmap                                 # photos -> sparse model (perf sfm), model_converter in tests
  libsqlite3-dev                         # COLMAP's database read back (the ghost repair)
  libopenmpi-dev openmpi-bin             # ranks across processes and nodes (mpirun perf reconstruct)
  clang                                  # libFuzzer target for the binary readers (optional)
  libcpp-httplib-dev libjs-three         # perf view: its HTTP server and the page's three.js
  chromium                               # perf view's page tests (headless)
  nodejs                                 # the page's scripts tested alone (field_parse_test, fly_test)
  python3-numpy python3-pil              # the GPU run scripts' dry runs (bench/masks_from_opacity.py)
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
