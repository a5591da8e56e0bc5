#!/usr/bin/env python3
"""Variants of the fragment rule (query/fragments.h) measured on trained models, instances protocol, object mode:

    PYTHONPATH=build/python python3 bench/fragment_variants.py SCENE:MODEL [SCENE:MODEL...]

For each model, the mean IoU over (test view, query) pairs of the names, masks = the chosen labels' rendered
opacity summed > 0.5 (as `hgs eval --protocol instances --mode object` scores; "cos0.2" reproduces it), for
the cosine margin 0.2 (the default), a margin in LERF relevancy (relD) and either (cos0.2|relD). The anchor and
the box test are the library's (query.h: choose_objects; label boxes replicated here). docs/results.md,
"Labels without Gaussians"."""
import os
import sys

import numpy as np

import hgs
from fragments import ious, load  # bench/fragments.py: the scene, the renders and the IoU of a set of labels


def boxes(m, L):
    """The library's label boxes (query/fragments.h): per label with >= 5 Gaussians of opacity > 0.3 as their hard
    id, the 5th and 95th percentile of their centres per axis."""
    z = np.asarray(m.object_ids).astype(int)
    op = np.asarray(m.opacities).ravel()
    mu = np.asarray(m.means)
    out = {}
    for k in range(L):
        v = mu[(z == k) & (op > 0.3)]
        if len(v) < 5:
            continue
        srt = np.sort(v, axis=0)
        out[k] = (srt[(len(v) - 1) * 5 // 100], srt[(len(v) - 1) * 95 // 100])
    return out


def meet(a, b):
    ga, gb = 0.2 * (a[1] - a[0]), 0.2 * (b[1] - b[0])
    return not np.any((a[0] - ga > b[1] + gb) | (b[0] - gb > a[1] + ga))


def variants(objs, B):
    """The labels each variant chooses: the anchor (the best label with a box) and the labels whose box meets its
    box and that are within the cosine margin 0.2 (the default), within d in relevancy, or either."""
    cos = np.array([o["cosine"] for o in objs])
    med = np.sort(cos)[len(cos) // 2]
    A = objs[next((i for i, o in enumerate(objs) if o["id"] in B), 0)]
    lead = max(0.0, A["cosine"] - med)

    def near(o):
        return A["id"] in B and o["id"] in B and o["id"] != A["id"] and meet(B[A["id"]], B[o["id"]])

    def by_cos(o):
        return A["cosine"] - o["cosine"] <= 0.2 * lead

    out = {"cos0.2": [A["id"]] + [o["id"] for o in objs if near(o) and by_cos(o)]}
    for d in (0.05, 0.1, 0.2):
        def by_rel(o):
            return A["relevancy"] - o["relevancy"] <= d
        out[f"rel{d}"] = [A["id"]] + [o["id"] for o in objs if near(o) and by_rel(o)]
        out[f"cos0.2|rel{d}"] = [A["id"]] + [o["id"] for o in objs if near(o) and (by_cos(o) or by_rel(o))]
    return out


def main(scene_dir, model_dir):
    s, m, queries, test, R, G = load(scene_dir, model_dir)
    B = boxes(m, R[test[0]].shape[2])
    session = hgs.QuerySession(s, m, "")
    acc = {}
    for phrase, k in queries.items():
        for name, chosen in variants(session.ask(phrase, 0.0, 0.2), B).items():
            acc.setdefault(name, []).extend(ious(R, G, test, chosen, k))
    return {n: 100 * np.mean(v) for n, v in acc.items()}


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    res = {}
    for arg in sys.argv[1:]:
        sc, md = arg.split(":")
        res[arg] = main(sc, md)
        print(os.path.basename(sc), md.split("/")[-1], " ".join(f"{n} {v:.2f}" for n, v in res[arg].items()),
              flush=True)
    names = list(next(iter(res.values())))
    print("MEAN", " ".join(f"{n} {np.mean([r[n] for r in res.values()]):.2f}" for n in names))
