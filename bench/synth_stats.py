#!/usr/bin/env python3
"""The statistics of a generated scene's simulated CLIP features and SAM2 masks, as docs/formats.md quotes them:

    python3 bench/synth_stats.py SCENE

Language (gt/objects.json names, text_embeddings.json, features/): the text-text cosine among the object names;
for the feature cells wholly inside one object, the cosine with its own name, with the best other name of the
scene, and how often the own name is the best (top-1); the same for each object's features pooled over its mask in
each view; the text cosine of each query set's phrases with their object's name (gt/queries.json).
Masks (gt/mask_ids.json of the realistic world): the share of visible (object, view) pairs without a mask id
showing the object, the number and mean length of those runs over the capture order, the mask IoU where shown, and
ids per object."""
import glob
import json
import os
import sys

import numpy as np
from PIL import Image


def language(d):
    te = json.load(open(d + "/text_embeddings.json"))
    te = te.get("embeddings", te)
    names = json.load(open(d + "/gt/objects.json"))
    ids = sorted(int(k) for k in names)
    T = {k: np.array(v, dtype=np.float64) for k, v in te.items() if isinstance(v, list)}
    N = np.stack([T[names[str(i)]] for i in ids])
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    tt = (N @ N.T)[np.triu_indices(len(ids), 1)]
    print(f"text-text among the names: mean {tt.mean():.3f}, min {tt.min():.3f}, max {tt.max():.3f}")
    own, other, top1, pown, pother, ptop = [], [], [], [], [], []
    for f in sorted(glob.glob(d + "/features/*.npy")):
        stem = os.path.basename(f)[:-4]
        F = np.load(f).astype(np.float64)
        gh, gw, _ = F.shape
        gt = np.array(Image.open(d + "/gt/instances/" + stem + ".png"))
        H, W = gt.shape
        cy, cx = np.arange(H) * gh // H, np.arange(W) * gw // W
        cells = (cy[:, None] * gw + cx[None, :]).ravel()
        up = F[np.minimum(cy, gh - 1)][:, np.minimum(cx, gw - 1)]
        for gi, k in enumerate(ids):
            m = gt == k
            if not m.any():
                continue
            inside = np.bincount(cells, m.ravel(), gh * gw) / np.bincount(cells, None, gh * gw)
            for c in np.nonzero(inside > 0.99)[0]:
                s = N @ F[c // gw, c % gw]
                own.append(s[gi]); other.append(np.delete(s, gi).max()); top1.append(np.argmax(s) == gi)
            z = up[m].mean(0)
            s = N @ (z / np.linalg.norm(z))
            pown.append(s[gi]); pother.append(np.delete(s, gi).max()); ptop.append(np.argmax(s) == gi)
    print(f"cells inside objects: {len(own)}, cosine with the own name {np.mean(own):.3f}, best other "
          f"{np.mean(other):.3f}, margin {np.mean(own) - np.mean(other):.3f}, top-1 {np.mean(top1):.2f}")
    print(f"pooled per (view, object): {len(pown)}, own {np.mean(pown):.3f}, best other {np.mean(pother):.3f}, "
          f"margin {np.mean(pown) - np.mean(pother):.3f}, top-1 {np.mean(ptop):.2f}")
    if os.path.exists(d + "/gt/queries.json"):
        for qs, m in json.load(open(d + "/gt/queries.json")).items():
            c = [T[p] @ N[ids.index(k)] / np.linalg.norm(T[p]) for p, k in m.items()]
            print(f"query set {qs}: {len(m)} phrases, text cosine with the name {np.mean(c):.3f}")


def masks(d):
    if not os.path.exists(d + "/gt/mask_ids.json"):
        return
    mi = json.load(open(d + "/gt/mask_ids.json"))
    K = len(json.load(open(d + "/gt/objects.json")))
    absent = {k: [] for k in range(1, K + 1)}
    ious, ids = [], {k: set() for k in range(1, K + 1)}
    for s in sorted(mi):
        gt = np.array(Image.open(d + "/gt/instances/" + s + ".png"))
        m = np.array(Image.open(d + "/masks/" + s + ".png"))
        for k in range(1, K + 1):
            if not (gt == k).any():
                continue
            shown = [int(i) for i, t in mi[s].items() if t.get("object") == k and t.get("kind", "object") != "surface"]
            ids[k].update(shown)
            absent[k].append(not shown)
            if shown:
                p, g = np.isin(m, shown), gt == k
                ious.append((p & g).sum() / (p | g).sum())
    runs, total, missing = [], 0, 0
    for seq in absent.values():
        r = 0
        for a in seq + [False]:
            if a:
                r += 1
            elif r:
                runs.append(r)
                r = 0
        total += len(seq)
        missing += sum(seq)
    print(f"visible (object, view) pairs {total}: {100 * missing / total:.1f} % without a mask showing the object, in "
          f"{len(runs)} runs of {np.mean(runs) if runs else 0:.2f} views; mask IoU where shown {np.mean(ious):.3f}; "
          f"{np.mean([len(v) for v in ids.values()]):.2f} ids per object")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    language(sys.argv[1])
    masks(sys.argv[1])
