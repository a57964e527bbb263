#!/usr/bin/env python3
"""Decodes the PNGs listed in DIR/bench.json (written by perf_bench_prep) into DIR/images.u8:
every view's RGB pixels as uint8, row-major [height, width, 3], views in bench.json order, one
after the other; and, when bench.json says "alpha", DIR/alpha.u8: every view's alpha as uint8
[height, width] in the same order. Runs on the GPU machine (python3 with numpy and Pillow), so that only the PNGs
travel there and perf_bench_gpu needs no image library.

    python3 bench/decode_images.py DIR
"""
import json
import os
import sys

import numpy as np
from PIL import Image


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    root = sys.argv[1]
    with open(os.path.join(root, "bench.json")) as f:
        data = json.load(f)
    bg = np.array(data["background"], dtype=np.float64)
    tmp = os.path.join(root, "images.u8.tmp")
    total = 0
    with open(tmp, "wb") as out:
        for v in data["views"]:
            im = Image.open(os.path.join(root, v["image"]))
            if im.mode in ("RGBA", "LA"):
                # The importer writes RGB; composite like it does, should an RGBA PNG appear.
                a = np.asarray(im.convert("RGBA"), dtype=np.float64) / 255.0
                rgb = a[..., :3] * a[..., 3:] + bg * (1.0 - a[..., 3:])
                px = np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)
            else:
                px = np.asarray(im.convert("RGB"), dtype=np.uint8)
            if px.shape != (v["height"], v["width"], 3):
                sys.exit(f"{v['image']}: {px.shape[1]}x{px.shape[0]}, bench.json says {v['width']}x{v['height']}")
            out.write(np.ascontiguousarray(px).tobytes())
            total += px.nbytes
    os.replace(tmp, os.path.join(root, "images.u8"))
    print(f"{os.path.join(root, 'images.u8')}: {len(data['views'])} views, {total / 2**20:.1f} MiB")
    if data.get("alpha"):
        tmp = os.path.join(root, "alpha.u8.tmp")
        with open(tmp, "wb") as out:
            for v in data["views"]:
                im = Image.open(os.path.join(root, v["alpha"]))
                # The importer writes 8- or 16-bit grey PNGs; scale to 0..255 like perf_bench_prep.
                a = np.asarray(im, dtype=np.float64)
                if a.ndim == 3:
                    a = a[..., -1]
                a = a / (65535.0 if a.max() > 255 or im.mode.startswith("I") else 255.0)
                px = np.clip(np.floor(a * 255.0 + 0.5), 0, 255).astype(np.uint8)
                if px.shape != (v["height"], v["width"]):
                    sys.exit(f"{v['alpha']}: {px.shape[1]}x{px.shape[0]}, bench.json says {v['width']}x{v['height']}")
                out.write(np.ascontiguousarray(px).tobytes())
        os.replace(tmp, os.path.join(root, "alpha.u8"))
        print(f"{os.path.join(root, 'alpha.u8')}: alpha of {len(data['views'])} views")


if __name__ == "__main__":
    main()
