#!/usr/bin/env python3
"""The labels a query ranks first on a synthetic scene, with what decides an object-mode answer (docs/ablation.md,
"The large single-scene losses ... read"):

    PYTHONPATH=build/python python3 bench/top_labels.py SCENE MODEL "QUERY" [N]

For the N (default 5) labels whose embeddings are closest to the query's text (QUERY one of gt/queries.json's
names): cosine, whether the answer chooses it, its Gaussians (hard ids), its mean IoU with the query's object over
the test views, and its support: the pixels it renders (opacity > 0.5) over the training views against the pixels
its mask id covers in their masks (`--anchor-support` compares the two)."""
import json
import os
import sys

import numpy as np
from PIL import Image

import fragments
import hgs


def main(scene_dir, model_dir, phrase, n):
    k = json.load(open(os.path.join(scene_dir, "gt", "queries.json")))["names"][phrase]
    s, m, _, test, A, G = fragments.load(scene_dir, model_dir)
    ids = np.asarray(m.object_ids)  # [N] hard label per Gaussian
    top = sorted(hgs.query(m, s, phrase).objects, key=lambda o: -o["cosine"])[:n]
    rendered = {o["id"]: 0 for o in top}
    masked = dict(rendered)
    for i, v in enumerate(s.views):
        if v.is_test:
            continue
        opacity = hgs.render(m, s, i, objects=True)["objects"]  # [H, W, L]
        mask = np.array(Image.open(os.path.join(scene_dir, "masks", os.path.splitext(v.name)[0] + ".png")))
        for label in rendered:
            rendered[label] += int((opacity[..., label] > 0.5).sum())
            masked[label] += int((mask == label).sum())
    for o in top:
        label = o["id"]
        print(f"{label:3d} {o['name'][:30]:30s} cosine {o['cosine']:.4f} chosen {int(o['chosen'])} "
              f"Gaussians {int((ids == label).sum()):6d} IoU {np.mean(fragments.ious(A, G, test, [label], k)):.3f} "
              f"rendered {rendered[label]} / mask {masked[label]} = {rendered[label] / max(masked[label], 1):.2f}")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]) if len(sys.argv) > 4 else 5)
