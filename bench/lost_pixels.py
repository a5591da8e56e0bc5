#!/usr/bin/env python3
"""Where model B's object-mode answers lose the pixels model A's answers cover (issue 59: BRO alone against all off
on the realistic world, docs/ablation.md). Over the test views and every name query of a generated scene, the
pixels of the true object that A's answer covers and B's does not ("lost"; "gained" the other way), and how many
of the lost ones lie (a) on the object's outer boundary, (b) within a pixel of a seam between two non-zero mask
ids inside the object in that view's SAM mask (a part cut off its whole, a re-born track), (c) where that mask
says background inside the object (an eroded edge, a lost track); each beside that region's share of the
object's pixels, so that a ratio above 1 says the losses gather there.

    PYTHONPATH=build/python python3 bench/lost_pixels.py SCENE MODEL_A MODEL_B"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from edge_bias import boundary  # noqa: E402
from fragments import truth  # noqa: E402

import hgs  # noqa: E402


def grow(x):
    """x [H, W] bool grown by one pixel (4-neighbours)."""
    p = np.pad(x, 1)
    return p[1:-1, 1:-1] | p[:-2, 1:-1] | p[2:, 1:-1] | p[1:-1, :-2] | p[1:-1, 2:]


def seams(m, g):
    """Pixels of object g [H, W] within a pixel of a change between two non-zero ids of mask m [H, W]."""
    cut = np.zeros_like(g)
    h = (m[:, 1:] != m[:, :-1]) & (m[:, 1:] > 0) & (m[:, :-1] > 0) & g[:, 1:] & g[:, :-1]
    v = (m[1:, :] != m[:-1, :]) & (m[1:, :] > 0) & (m[:-1, :] > 0) & g[1:, :] & g[:-1, :]
    cut[:, 1:] |= h
    cut[:, :-1] |= h
    cut[1:, :] |= v
    cut[:-1, :] |= v
    return grow(cut) & g


def main(scene_dir, model_a, model_b):
    s = hgs.Scene.load(scene_dir)
    queries = json.load(open(os.path.join(scene_dir, "gt", "queries.json")))["names"]
    test = [i for i, v in enumerate(s.views) if v.is_test]
    sessions = [hgs.QuerySession(s, hgs.Model.load(m), "") for m in (model_a, model_b)]
    gt = {i: truth(scene_dir, s, i) for i in test}
    masks = {i: np.asarray(s.mask(i)) for i in test}
    regions = ["on the outer boundary", "at a seam", "where the mask says 0"]
    n = {"object": 0, "lost": 0, "gained": 0}
    n.update({r: 0 for r in regions})
    n.update({"lost " + r: 0 for r in regions})
    for name, k in queries.items():
        chosen = [[o["id"] for o in se.ask(name) if o["chosen"]] for se in sessions]
        for i in test:
            g = gt[i] == k
            if not g.any():
                continue
            a, b = (np.asarray(se.object_opacity(i, ch)) > 0.5 for se, ch in zip(sessions, chosen))
            m = masks[i]
            lost = g & a & ~b
            n["object"] += g.sum()
            n["lost"] += lost.sum()
            n["gained"] += (g & b & ~a).sum()
            for r, region in zip(regions, (boundary(g), seams(m, g), g & (m == 0))):
                n[r] += region.sum()
                n["lost " + r] += (lost & region).sum()
    print(f"object pixels {n['object']}, lost {n['lost']} ({100 * n['lost'] / n['object']:.1f} %), "
          f"gained {n['gained']} ({100 * n['gained'] / n['object']:.1f} %)")
    for r in regions:
        share, part = n[r] / n["object"], n["lost " + r] / max(1, n["lost"])
        print(f"  lost {r}: {n['lost ' + r]} ({100 * part:.0f} % of lost; the region is {100 * share:.0f} % of the "
              f"object: {part / share if share else float('nan'):.1f}x)")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
