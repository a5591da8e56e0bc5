#!/usr/bin/env python3
"""Where object mode loses on a synthetic scene, and the fragment rule (query/fragments.h) measured against the best
label alone (docs/results.md, "Fragments of one object"):

    PYTHONPATH=build/python python3 bench/fragments.py SCENE MODEL [QUERY_SET] [MARGIN...]

For every query of the set (gt/queries.json; default names): the labels the answer chooses and their mean IoU
with the object over the test views, the best single label's IoU, and the union of every label that is mostly
that object (what an answer could reach if it found all the object's fragments). Then the mean IoU over (test
view, query) pairs of the answer with the fragment rule at each margin (default 0 0.05 0.1 0.15 0.2; 0 = the best
label alone), as `hgs eval --fragment-margin M` scores object mode (masks: chosen opacity summed > 0.5)."""
import json
import os
import sys

import numpy as np
from PIL import Image

import hgs


def truth(scene_dir, s, i):
    """The ground-truth instance map of view i of scene s (loaded from scene_dir): [H, W] object ids."""
    stem = os.path.splitext(s.views[i].name)[0]
    return np.array(Image.open(os.path.join(scene_dir, "gt", "instances", stem + ".png")))


def load(scene_dir, model_dir, qset="names"):
    """The scene, the model, the query set {phrase: object id}, the test views, each test view's rendered label
    opacities A[i] [H, W, L] and ground-truth instance map G[i] [H, W]."""
    s = hgs.Scene.load(scene_dir)
    m = hgs.Model.load(model_dir)
    qfile = os.path.join(scene_dir, "gt", "queries.json")
    if os.path.exists(qfile):
        queries = json.load(open(qfile))[qset]
    else:  # a simple-world scene: the names of gt/objects.json
        queries = {n: int(k) for k, n in json.load(open(os.path.join(scene_dir, "gt", "objects.json"))).items()}
    test = [i for i, v in enumerate(s.views) if v.is_test]
    A, G = {}, {}
    for i in test:
        A[i] = hgs.render(m, s, i, objects=True)["objects"]
        G[i] = truth(scene_dir, s, i)
    return s, m, queries, test, A, G


def ious(A, G, test, chosen, k):
    """IoU of the chosen labels' summed opacity > 0.5 with object k, in each test view that shows k."""
    out = []
    for i in test:
        g = G[i] == k
        if g.any():
            p = A[i][..., chosen].sum(-1) > 0.5
            out.append((p & g).sum() / (p | g).sum())
    return out


def main(scene_dir, model_dir, qset, margins):
    s, m, queries, test, A, G = load(scene_dir, model_dir, qset)
    names = json.load(open(os.path.join(scene_dir, "masks", "objects.json")))
    L = A[test[0]].shape[2]

    def iou(chosen, k):
        return ious(A, G, test, chosen, k)

    rows = []
    for phrase, k in sorted(queries.items(), key=lambda x: x[1]):
        chosen = [o["id"] for o in hgs.query(m, s, phrase).objects if o["chosen"]]
        inside = {l: sum(((A[i][..., l] > 0.5) & (G[i] == k)).sum() for i in test) for l in range(1, L)}
        total = {l: sum((A[i][..., l] > 0.5).sum() for i in test) for l in range(1, L)}
        mostly = [l for l in range(1, L) if total[l] > 0 and inside[l] / total[l] > 0.5]
        single = {l: np.mean(iou([l], k)) for l in range(1, L)}
        best = max(single, key=single.get)
        rows.append((np.mean(iou(chosen, k)), single[best], np.mean(iou(mostly, k)) if mostly else 0.0))
        print(f"{phrase:24s} chosen {chosen} IoU {rows[-1][0]:.2f} | best label {best} ({names.get(str(best), '?')}) "
              f"{rows[-1][1]:.2f} | labels mostly it {mostly} together {rows[-1][2]:.2f}")
    r = np.array(rows)
    print(f"mean over queries: chosen {r[:, 0].mean():.4f}, best single label {r[:, 1].mean():.4f}, "
          f"its labels together {r[:, 2].mean():.4f}")
    session = hgs.QuerySession(s, m, "")
    for margin in margins:
        pairs = []
        for phrase, k in queries.items():
            chosen = [o["id"] for o in session.ask(phrase, 0.0, margin) if o["chosen"]]
            pairs += iou(chosen, k)
        print(f"fragment margin {margin:.2f}: mean IoU {np.mean(pairs):.4f} over {len(pairs)} (view, query) pairs")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    qs = sys.argv[3] if len(sys.argv) > 3 else "names"
    ms = [float(x) for x in sys.argv[4:]] or [0.0, 0.05, 0.1, 0.15, 0.2]
    main(sys.argv[1], sys.argv[2], qs, ms)
