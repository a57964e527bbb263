#!/usr/bin/env bash
# Two perf builds on one workspace, back to back: BASE, NEW, BASE, NEW (ROUNDS rounds), each a
# fresh copy of the imported workspace, so that the VM's drift falls on both sides alike.
# Prints each run's solver seconds (log.jsonl's last iteration), CG seconds and final held-out
# PSNR; pass --eval-every 1 (or let levels end) so that a PSNR is logged.
#   usage: bench/ab_reconstruct.sh BASE_PERF NEW_PERF WORKSPACE [perf reconstruct options...]
#   e.g.   bench/ab_reconstruct.sh /tmp/perf_base build/perf .data/lg100 --levels 3 --level-iterations 4,4,8 --eval-every 1
set -euo pipefail
if [ $# -lt 3 ]; then
  sed -n '2,7p' "$0" >&2
  exit 2
fi
base=$1 new=$2 src=$3
shift 3
rounds=${ROUNDS:-2}
scratch=$(mktemp -d "${TMPDIR:-/tmp}/perf_ab.XXXXXX")
trap 'rm -rf "$scratch"' EXIT
for f in "$base" "$new"; do [ -x "$f" ] || { echo "error: $f is not an executable perf" >&2; exit 2; }; done
[ -f "$src/scene.json" ] || { echo "error: $src/scene.json not found: WORKSPACE must be made by perf import" >&2; exit 2; }
for round in $(seq "$rounds"); do
  for side in base new; do
    bin=$base
    [ "$side" = new ] && bin=$new
    ws=$scratch/ws
    rm -rf "$ws" && mkdir "$ws"
    for item in images alpha masks inputs.json scene.json; do
      [ -e "$src/$item" ] && cp -r "$src/$item" "$ws/"
    done
    "$bin" reconstruct "$ws" -q "$@" > "$scratch/out.txt" 2>&1 || { cat "$scratch/out.txt" >&2; exit 1; }
    python3 - "$ws/recon/log.jsonl" "$side" "$round" <<'PY'
import json, sys
events = [json.loads(line) for line in open(sys.argv[1]) if line.strip()]
its = [e for e in events if e.get("event") == "iteration"]
scores = [e["test_psnr"] for e in events if e.get("test_psnr") is not None]
cg = sum(e["seconds"]["cg"] for e in its)
psnr = f"{scores[-1]:.3f} dB" if scores else "none logged"
print(f"{sys.argv[2]:4s} round {sys.argv[3]}: solver {its[-1]['elapsed']:.1f} s, cg {cg:.1f} s, held-out {psnr}")
PY
  done
done
