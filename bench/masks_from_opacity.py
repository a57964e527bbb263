#!/usr/bin/env python3
"""Binary masks from perf render's box-opacity images (<name>_opacity.png, 16-bit), as perf export
thresholds them (0.7, the paper's rule), written small (1-bit PNG, <name>.png) so that a GPU run's
masks of every photo come back in one file. On the GPU machine (Pillow, numpy), by perf_gpu_run.sh.
Usage: masks_from_opacity.py RENDERS_DIR OUT_DIR [THRESHOLD]"""
import os
import sys

import numpy as np
from PIL import Image


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    src, dst = sys.argv[1], sys.argv[2]
    threshold = float(sys.argv[3]) if len(sys.argv) == 4 else 0.7
    os.makedirs(dst, exist_ok=True)
    names = sorted(f for f in os.listdir(src) if f.endswith("_opacity.png"))
    if not names:
        sys.exit(f"masks_from_opacity.py: no *_opacity.png in {src}")
    for f in names:
        opacity = np.asarray(Image.open(os.path.join(src, f)), dtype=np.float64) / 65535.0
        mask = Image.fromarray(opacity >= threshold)  # mode "1"
        mask.save(os.path.join(dst, f[: -len("_opacity.png")] + ".png"), optimize=True)
    print(f"{len(names)} masks at opacity >= {threshold} in {dst}")


if __name__ == "__main__":
    main()
