#!/usr/bin/env python3
"""Where an object's edges sit, in the masks and in trained models, against the truth (issue 59: BRO's loss on the
realistic world, docs/ablation.md). For every object of a generated scene:

- the masks' edge offset: over the training views, (pixels of every mask id the truth says is this object, from
  gt/mask_ids.json: its object, track and part ids) minus (its true pixels), divided by the true boundary's length
  (pixels of the object with a 4-neighbour outside it): the mean outward shift of the masks' edge, in pixels
  (> 0: SAM's masks grow the object; the realistic world draws one signed edge bias per object, docs/formats.md);
- for each MODEL, the same offset of its answer to the object's name (`hgs.query`, the chosen labels' opacity
  > 0.5) over the test views, and the answer's IoU with the object.

    PYTHONPATH=build/python python3 bench/edge_bias.py SCENE MODEL [MODEL...]

Prints one row per object and, per model, the correlation of its offsets with the masks' (over the objects) and
the mean IoU."""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fragments import truth  # noqa: E402  (the scene's ground-truth instance maps)

import hgs  # noqa: E402


def boundary(g):
    """Pixels of g [H, W] bool with a 4-neighbour outside it (the image border counts as outside)."""
    p = np.pad(g, 1)
    inner = p[1:-1, 1:-1] & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
    return g & ~inner


def main(scene_dir, models):
    s = hgs.Scene.load(scene_dir)
    queries = json.load(open(os.path.join(scene_dir, "gt", "queries.json")))["names"]
    mids = json.load(open(os.path.join(scene_dir, "gt", "mask_ids.json")))
    train = [i for i, v in enumerate(s.views) if not v.is_test]
    test = [i for i, v in enumerate(s.views) if v.is_test]
    objects = sorted(set(queries.values()))
    # The masks' offset per object: sums over the training views.
    diff, perim = {k: 0.0 for k in objects}, {k: 0.0 for k in objects}
    for i in train:
        stem = os.path.splitext(s.views[i].name)[0]
        m, g = np.asarray(s.mask(i)), truth(scene_dir, s, i)
        ids = mids.get(stem, {})
        for k in objects:
            gk = g == k
            if not gk.any():
                continue
            mine = [int(a) for a, d in ids.items() if d.get("object") == k and d.get("kind") != "surface"]
            mk = np.isin(m, mine)
            diff[k] += float(mk.sum()) - float(gk.sum())
            perim[k] += float(boundary(gk).sum())
    mask_off = {k: diff[k] / perim[k] if perim[k] else float("nan") for k in objects}
    rows = {k: [mask_off[k]] for k in objects}
    names = {k: p for p, k in queries.items()}
    gt = {i: truth(scene_dir, s, i) for i in test}
    for model_dir in models:
        m = hgs.Model.load(model_dir)
        session = hgs.QuerySession(s, m, "")
        for k in objects:
            chosen = [o["id"] for o in session.ask(names[k]) if o["chosen"]]
            d = p_ = 0.0
            ious = []
            for i in test:
                g = gt[i] == k
                if not g.any():
                    continue
                a = np.asarray(session.object_opacity(i, chosen)) > 0.5  # the chosen labels' opacity, summed
                d += float(a.sum()) - float(g.sum())
                p_ += float(boundary(g).sum())
                ious.append((a & g).sum() / max(1, (a | g).sum()))
            rows[k] += [d / p_ if p_ else float("nan"), float(np.mean(ious)) if ious else float("nan")]
    head = " | ".join(f"{os.path.basename(os.path.normpath(x))}: offset, IoU" for x in models)
    print(f"| object | masks' offset (px) | {head} |")
    print("|---|---|" + "---|" * len(models))
    for k in objects:
        r = rows[k]
        cells = " | ".join(f"{r[1 + 2 * j]:+.2f}, {r[2 + 2 * j]:.2f}" for j in range(len(models)))
        print(f"| {names[k]} | {r[0]:+.2f} | {cells} |")
    for j, x in enumerate(models):
        a = np.array([[rows[k][0], rows[k][1 + 2 * j]] for k in objects if np.isfinite(rows[k][1 + 2 * j])])
        c = np.corrcoef(a[:, 0], a[:, 1])[0, 1] if len(a) > 2 else float("nan")
        iou = np.nanmean([rows[k][2 + 2 * j] for k in objects])
        print(f"{os.path.basename(os.path.normpath(x))}: correlation of the answers' offsets with the masks' {c:+.2f}, "
              f"mean IoU {iou:.4f}")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
