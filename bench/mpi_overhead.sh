#!/usr/bin/env bash
# Ranks against threads on one machine (issue 17, docs/scaling.md): `perf reconstruct` with
# 1 process x T threads against `mpirun -np T` x 1 thread on the same workspace, alternating
# A B A B so that a noisy machine hits both alike. Prints the seconds per GN iteration of each
# level, their ratio, and the bytes every rank sent to the sums per GN iteration (log.jsonl).
#
#   [MPIRUN_ARGS="--bind-to none"] bench/mpi_overhead.sh WORKSPACE [T=2] [LEVELS=2] [ITERATIONS=6] [ROUNDS=2]
# WORKSPACE: made by perf import (e.g. lego at --downscale 16); it is copied, not written.
set -euo pipefail
ws=${1:?usage: bench/mpi_overhead.sh WORKSPACE [threads] [levels] [iterations] [rounds]}
t=${2:-2}; levels=${3:-2}; iters=${4:-6}; rounds=${5:-2}
perf=${PERF:-$(dirname "$0")/../build/perf}
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
args="--device cpu --levels $levels --iterations $iters -q"
for r in $(seq "$rounds"); do
  rm -rf "$tmp/a" "$tmp/b"; cp -r "$ws" "$tmp/a"; cp -r "$ws" "$tmp/b"
  rm -rf "$tmp/a/recon" "$tmp/b/recon"
  "$perf" reconstruct "$tmp/a" $args -j "$t"
  mpirun -np "$t" ${MPIRUN_ARGS:-} "$perf" reconstruct "$tmp/b" $args -j 1
  python3 - "$tmp/a/recon/log.jsonl" "$tmp/b/recon/log.jsonl" "$r" "$t" <<'PY'
import json, sys
def per_level(path, event="iteration"):
    its = {}
    for line in open(path):
        j = json.loads(line)
        if j.get("event") == event:
            its.setdefault(j["level"], []).append(j)
    return its
a, b = per_level(sys.argv[1]), per_level(sys.argv[2])
levels_b = per_level(sys.argv[2], "level")
r, t = sys.argv[3], sys.argv[4]
for level in sorted(a):
    # The first iteration of a level includes no setup (that is in the level's seconds), but
    # its Jacobian cache fill makes it slower on both sides alike; all are averaged.
    sa = sum(j["seconds"]["total"] for j in a[level]) / len(a[level])
    sb = sum(j["seconds"]["total"] for j in b[level]) / len(b[level])
    nbytes = b[level][-1].get("summed_bytes", 0)
    print(f"round {r} level {level} (n={a[level][0]['n']}): 1 x {t} threads {sa:.3f} s/iteration, "
          f"{t} ranks x 1 thread {sb:.3f} s/iteration, ratio {sb / sa:.3f}; "
          f"{nbytes / 2**20:.1f} MiB summed per rank per GN iteration; "
          f"cost {a[level][-1]['cost']:.6g} vs {b[level][-1]['cost']:.6g}; "
          f"each rank's pass seconds {[round(s, 2) for s in levels_b[level][-1]['rank_pass_seconds']]}, "
          f"in the sums {[round(s, 2) for s in levels_b[level][-1]['rank_sum_seconds']]}")
PY
done
