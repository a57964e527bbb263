#!/usr/bin/env bash
# README command 2 (and .ci/run): install what is missing, build, run the test suite.
# Tests labelled `slow` are left out unless PERF_TEST_ALL=1; `gpu` tests skip without a GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
cd build
if [ "${PERF_TEST_ALL:-0}" = "1" ]; then
  ctest --output-on-failure -j "$(nproc)"
else
  ctest --output-on-failure -j "$(nproc)" -LE slow
fi
