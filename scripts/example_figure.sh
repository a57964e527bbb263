#!/usr/bin/env bash
# docs/example.png from a workspace of the README's first command: a held-out view rendered, its
# photo, our binary mask of it and the cut-out over grey, side by side (oiiotool, Debian's
# openimageio-tools). Usage: scripts/example_figure.sh [WORKSPACE] [VIEW] [OUT]
set -euo pipefail
ws=${1:-out/bonsai_mini}
view=${2:-DSCF5656}
out=${3:-docs/example.png}
# The photo as the user gave it (scene.json source_path), at the masks' size.
photo=$(python3 -c "import json, sys
s = json.load(open(sys.argv[1] + '/scene.json'))
print([i['source_path'] for i in s['images'] if i['name'].rsplit('.', 1)[0] == sys.argv[2]][0])" "$ws" "$view")
size=$(oiiotool --info "$ws/masks/binary/$view.png" | sed -E 's/.*: *([0-9]+) x +([0-9]+).*/\1x\2/')
w=${size%x*}
h=${size#*x}
oiiotool "$ws/renders/test/$view.png" --resize "$size" --ch R,G,B,A=1.0 \
  "$photo" --resize "$size" --ch R,G,B,A=1.0 \
  "$ws/masks/binary/$view.png" --ch R=Y,G=Y,B=Y,A=1.0 \
  "$ws/foreground/$view.png" --pattern constant:color=0.5,0.5,0.5,1 "$size" 4 --over --ch R,G,B,A=1.0 \
  --mosaic:pad=10 4x1 --pattern constant:color=1,1,1,1 "$((4 * w + 30))x$h" 4 --over --ch R,G,B -o "$out"
echo "wrote $out"
