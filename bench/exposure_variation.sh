#!/usr/bin/env bash
# Per-photo exposure (issue 16), measured: a copy of a COLMAP photo set whose photos are re-exposed
# by a smooth function of their capture order (each channel's gain 1 +- 0.2 and offset +- 0.03 on
# the stored values, as auto-exposure and white balance drift along a capture; held-out photos
# too), reconstructed with --exposure off and on. Prints held-out PSNR and SSIM of each run (the
# held-out views take their nearest training photo's transform when on).
#
#   bench/exposure_variation.sh [IMAGES SPARSE OUT PRESET]
#   default: examples/bonsai_mini/images examples/bonsai_mini/sparse/0 /tmp/perf_exposure preview
# Needs the perf build and oiiotool (openimageio-tools). 2-core VM: about 2 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
images=${1:-examples/bonsai_mini/images}
sparse=${2:-examples/bonsai_mini/sparse/0}
out=${3:-/tmp/perf_exposure}
preset=${4:-preview}
rm -rf "$out"
mkdir -p "$out/images"
k=0
for f in $(ls "$images" | sort); do
  gains=$(awk -v k=$k 'BEGIN { printf "%.4f,%.4f,%.4f", 1 + 0.2 * sin(k / 3.0), 1 + 0.2 * sin(k / 3.0 + 1), 1 + 0.15 * sin(k / 4.0 + 2) }')
  offsets=$(awk -v k=$k 'BEGIN { printf "%.4f,%.4f,%.4f", 0.03 * cos(k / 5.0), 0.02 * cos(k / 5.0 + 1), 0.03 * cos(k / 5.0 + 2) }')
  oiiotool "$images/$f" --mulc "$gains" --addc "$offsets" --clamp:min=0:max=1 -o "$out/images/$f"
  k=$((k + 1))
done
for e in off on; do
  ./build/perf run --colmap "$sparse" --images "$out/images" --workspace "$out/ws_$e" --preset "$preset" \
    --exposure "$e" --log-level quiet
  python3 - "$out/ws_$e" "$e" <<'PY'
import json, sys
ws, e = sys.argv[1], sys.argv[2]
r = json.load(open(ws + "/report.json"))
m = r["mean"] if "mean" in r else r
recon = json.load(open(ws + "/recon/recon.json"))
print(f"exposure {e}: held-out PSNR {m['psnr']:.2f} dB, SSIM {m['ssim']:.3f}, "
      f"PSNR in mask {m.get('psnr_masked', 0):.2f} dB; gains {recon['exposures']['gain_range']}; "
      f"solve {recon['solve_seconds']:.1f} s")
PY
done
