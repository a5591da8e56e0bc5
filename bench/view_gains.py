#!/usr/bin/env python3
"""Per-view exposure of a trained model against its photos: the least-squares gain g_c of each colour channel,
photo ~ g_c x render (through the origin), for every view that `hgs render --split all` wrote.

    hgs render SCENE MODEL --downscale 4 --split all --out RENDER
    python3 bench/view_gains.py SCENE RENDER [--test-every 8]

A capture whose frames were shot at different exposures leaves gains away from 1 on the training views that the
model cannot follow (it has one colour per point and direction); gains within a few tenths of a per cent say the
photos agree with each other (docs/scaling.md, "Floaters"). The photos are box-downscaled to the render's size.
Views are numbered in the order of metrics.json; every --test-every-th (0, 8, 16, ...) is marked held out, as
hgs's split does. Written here because no packaged tool fits a per-image gain; numpy and PIL (Debian's
python3-matplotlib brings python3-pil) only.
"""
import argparse
import json
import os

import numpy as np
from PIL import Image


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("render", help="an `hgs render --split all` folder (metrics.json, renders/)")
    ap.add_argument("--test-every", type=int, default=8)
    a = ap.parse_args()
    views = json.load(open(os.path.join(a.render, "metrics.json")))["views"]
    train = []
    print("view      held-out  psnr   gain R  gain G  gain B")
    for i, v in enumerate(views):
        stem = os.path.splitext(v["name"])[0]
        r = np.asarray(Image.open(os.path.join(a.render, "renders", stem + ".png")).convert("RGB"), np.float64) / 255
        photo = Image.open(os.path.join(a.scene, "images", v["name"])).convert("RGB")
        p = np.asarray(photo.resize((r.shape[1], r.shape[0]), Image.BOX), np.float64) / 255
        g = [float((r[..., c] * p[..., c]).sum() / max((r[..., c] ** 2).sum(), 1e-12)) for c in range(3)]
        held = a.test_every > 0 and i % a.test_every == 0
        if not held:
            train.append(np.mean(g))
        print(f"{stem:9s} {'yes' if held else '   ':8s} {v['psnr']:6.2f}  " + "  ".join(f"{x:.4f}" for x in g))
    t = np.array(train)
    print(f"training views: {len(t)}, mean gain {t.min():.4f} .. {t.max():.4f}, standard deviation {t.std():.4f}")


if __name__ == "__main__":
    main()
