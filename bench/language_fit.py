#!/usr/bin/env python3
"""How a trained hybrid model's language fits the reference features (docs/ablation.md, "The no-SCL rows' 3D-OVS
pixel collapse, diagnosed"):

    PYTHONPATH=build/python python3 bench/language_fit.py SCENE MODEL

prints, on every 4th training view, the cosine of the raw language map sum_n f_n alpha T with the reference
features S^ref (pixels with alpha > 0.5), the same for hgs's object-embedding map sum_k A_k e_k, each object's
embedding e_k against its own and the other objects' pooled references, the embeddings' mean pairwise cosine (and
the references'), and for every 3D-OVS class that names a mask object whether that class is the best class of the
object's embedding (what pixel mode's argmax over classes needs)."""
import json
import os
import sys

import numpy as np

import hgs


def main(scene_dir, model_dir):
    s = hgs.Scene.load(scene_dir)
    m = hgs.Model.load(model_dir)
    q = np.asarray(m.object_probs, np.float64)
    f = np.asarray(m.language, np.float64)
    op = np.asarray(m.opacities, np.float64)
    E = (q * op[:, None]).T @ f
    E /= np.linalg.norm(E, axis=1, keepdims=True) + 1e-12
    L = E.shape[0]
    zref = np.zeros_like(E)
    cnt = np.zeros(L)
    raw_cos, obj_cos = [], []
    for i in [i for i, v in enumerate(s.views) if not v.is_test][::4]:
        out = hgs.render(m, s, i, objects=True, language=True)
        F = out["language"].astype(np.float64)
        R = s.features(i).astype(np.float64)
        Rn = R / (np.linalg.norm(R, axis=-1, keepdims=True) + 1e-12)
        msk = out["alpha"] > 0.5
        Fn = F / (np.linalg.norm(F, axis=-1, keepdims=True) + 1e-12)
        raw_cos.append((Fn * Rn).sum(-1)[msk].mean())
        O = out["objects"].astype(np.float64) @ E
        On = O / (np.linalg.norm(O, axis=-1, keepdims=True) + 1e-12)
        obj_cos.append((On * Rn).sum(-1)[msk].mean())
        lab = s.mask(i)
        for k in range(L):
            mk = lab == k
            if mk.sum() >= 16:
                zref[k] += R[mk].mean(0)
                cnt[k] += 1
    zn = zref / (np.linalg.norm(zref, axis=1, keepdims=True) + 1e-12)
    present = [k for k in range(1, L) if cnt[k] > 0]
    off = lambda M: (M.sum() - np.trace(M)) / (len(present) ** 2 - len(present))
    C = E[present] @ zn[present].T
    print(f"raw map cos with S^ref {np.mean(raw_cos):.3f}; object-embedding map {np.mean(obj_cos):.3f}; "
          f"e_k with own pooled reference {np.diag(C).mean():.3f}, with others' {off(C):.3f}; "
          f"e_k pairwise {off(E[present] @ E[present].T):.3f} (references {off(zn[present] @ zn[present].T):.3f})")
    classes_file = os.path.join(scene_dir, "segmentations", "classes.txt")
    if not os.path.exists(classes_file):
        return
    te = json.load(open(os.path.join(scene_dir, "text_embeddings.json")))
    te = te.get("embeddings", te)
    names = json.load(open(os.path.join(scene_dir, "masks", "objects.json")))
    classes = [c.strip() for c in open(classes_file) if c.strip()]
    T = np.array([te[c] for c in classes], np.float64)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    wins = n = 0
    for k, name in names.items():
        if name not in classes or int(k) >= L:
            continue
        c = T @ E[int(k)]
        best = classes[int(np.argmax(c))]
        n += 1
        wins += best == name
        print(f"  {name:24s} own class {c[classes.index(name)]:.3f}, best class {best} {c.max():.3f}")
    print(f"own class the best class of its object's embedding: {wins} of {n}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
