#!/usr/bin/env python3
"""Variants of the fragment rule (query/fragments.h) measured on trained models, instances protocol, object mode:

    PYTHONPATH=build/python python3 bench/fragment_variants.py SCENE:MODEL [SCENE:MODEL...]

For each model, the mean IoU over (test view, query) pairs of the names, masks = the chosen labels' rendered
opacity summed > 0.5 (as `hgs eval --protocol instances --mode object` scores; "cos0.2" reproduces it), for
the cosine margin 0.2 (the default), a margin in LERF relevancy (relD) and either (cos0.2|relD). The anchor and
the box test are the library's (query.h: choose_objects; label boxes replicated here). docs/results.md,
"Labels without Gaussians"."""
import json, os, sys
import numpy as np
from PIL import Image
import hgs

def boxes(m, L):
    z = np.asarray(m.object_ids).astype(int); op = np.asarray(m.opacities).ravel(); mu = np.asarray(m.means)
    out = {}
    for k in range(L):
        sel = (z == k) & (op > 0.3)
        if sel.sum() < 5: continue
        v = mu[sel]; n = len(v)
        lo = np.sort(v, axis=0)[(n - 1) * 5 // 100]; hi = np.sort(v, axis=0)[(n - 1) * 95 // 100]
        out[k] = (lo, hi)
    return out

def meet(a, b):
    ga, gb = 0.2 * (a[1] - a[0]), 0.2 * (b[1] - b[0])
    return not np.any((a[0] - ga > b[1] + gb) | (b[0] - gb > a[1] + ga))

def variants(objs, B):
    cos = np.array([o["cosine"] for o in objs]); med = np.sort(cos)[len(cos) // 2]
    a = next((i for i, o in enumerate(objs) if o["id"] in B), 0)
    A = objs[a]; out = {}
    def near(o): return A["id"] in B and o["id"] in B and o["id"] != A["id"] and meet(B[A["id"]], B[o["id"]])
    lead = max(0.0, A["cosine"] - med)
    out["cos0.2"] = [A["id"]] + [o["id"] for o in objs if near(o) and A["cosine"] - o["cosine"] <= 0.2 * lead]
    for d in (0.05, 0.1, 0.2):
        out[f"rel{d}"] = [A["id"]] + [o["id"] for o in objs if near(o) and A["relevancy"] - o["relevancy"] <= d]
        out[f"cos0.2|rel{d}"] = [A["id"]] + [o["id"] for o in objs if near(o) and (
            A["cosine"] - o["cosine"] <= 0.2 * lead or A["relevancy"] - o["relevancy"] <= d)]
    return out

def main(scene_dir, model_dir):
    s = hgs.Scene.load(scene_dir); m = hgs.Model.load(model_dir)
    q = json.load(open(os.path.join(scene_dir, "gt", "queries.json")))["names"]
    test = [i for i, v in enumerate(s.views) if v.is_test]
    R, G = {}, {}
    for i in test:
        R[i] = hgs.render(m, s, i, objects=True)["objects"]
        G[i] = np.array(Image.open(os.path.join(scene_dir, "gt", "instances", os.path.splitext(s.views[i].name)[0] + ".png")))
    L = R[test[0]].shape[2]; B = boxes(m, L); sess = hgs.QuerySession(s, m, "")
    acc = {}
    for phrase, k in q.items():
        objs = sess.ask(phrase, 0.0, 0.2)
        for name, ch in variants(objs, B).items():
            for i in test:
                g = G[i] == k
                if not g.any(): continue
                p = R[i][..., ch].sum(-1) > 0.5
                acc.setdefault(name, []).append((p & g).sum() / (p | g).sum())
    return {n: 100 * np.mean(v) for n, v in acc.items()}

if __name__ == "__main__":
    res = {}
    for arg in sys.argv[1:]:
        sc, md = arg.split(":")
        r = main(sc, md); res[arg] = r
        print(os.path.basename(sc), md.split("/")[-1], " ".join(f"{n} {v:.2f}" for n, v in r.items()), flush=True)
    names = list(next(iter(res.values())))
    print("MEAN", " ".join(f"{n} {np.mean([r[n] for r in res.values()]):.2f}" for n in names))
