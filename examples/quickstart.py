#!/usr/bin/env python3
"""hgs from Python in a few lines: a synthetic scene, 300 training steps of Hybrid Gaussians, a text query, and a
matplotlib figure of the answer (docs/python.md).

    PYTHONPATH=build/python python3 examples/quickstart.py --out quickstart/

writes quickstart/scene (the synthetic scene), quickstart/model (the trained model) and quickstart/quickstart.png.
With --check it exits with status 1 unless the query's mask overlaps the object's own mask (IoU >= 0.5), as the
test run (ctest python_quickstart) does.
"""

import argparse
import os
import sys

import matplotlib

matplotlib.use("Agg")  # files only, no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import hgs  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="quickstart", help="output folder")
    ap.add_argument("--iters", type=int, default=300, help="training steps")
    ap.add_argument("--check", action="store_true", help="exit 1 unless the answer's mask IoU is >= 0.5")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    # 1. A synthetic tabletop: 16 views, 4 objects, simulated SAM2 masks and CLIP features, text embeddings.
    scene_dir = os.path.join(args.out, "scene")
    if not os.path.exists(os.path.join(scene_dir, "text_embeddings.json")):
        hgs.synth(scene_dir, views=16, width=160, height=120, objects=4, points=4000, feature_dim=32,
                  noise="low", supersample=1)
    scene = hgs.Scene.load(scene_dir)

    # 2. Train, recording the loss every 10 steps through the callback.
    curve = []
    model = hgs.train(scene, out=os.path.join(args.out, "model"), iters=args.iters, callback_every=10,
                      callback=lambda info: curve.append((info["iteration"], info["loss"])))

    # 3. Ask for an object by name; render one held-out view.
    object_id, text = sorted(scene.object_names.items())[0]
    answer = hgs.query(model, scene, text)
    view = scene.test_indices[0] if scene.test_indices else 0
    render = hgs.render(model, scene, view)
    mask = answer.mask(view)
    truth = scene.mask(view) == object_id
    iou = (mask & truth).sum() / max(1, (mask | truth).sum())
    print(f'"{text}" -> object {answer.best["id"]} ({answer.best["name"]}), relevancy '
          f'{answer.best["relevancy"]:.3f}; mask IoU {iou:.3f} in view {scene.views[view].name}')

    # 4. The figure.
    image = scene.image(view)
    overlay = image.astype(np.float32) / 255
    overlay[mask] = 0.5 * overlay[mask] + 0.5 * np.array([1.0, 0.1, 0.1])
    fig, ax = plt.subplots(1, 5, figsize=(20, 3.6))
    panels = [(image, "image"), (np.clip(render["rgb"], 0, 1), "render"),
              (answer.opacity(view), f'opacity of "{text}"'), (overlay, f"mask (IoU {iou:.2f})")]
    for a, (img, title) in zip(ax, panels):
        a.imshow(img, cmap="turbo" if img.ndim == 2 else None, vmin=0, vmax=1)
        a.set_title(title)
        a.axis("off")
    ax[4].plot(*zip(*curve))
    ax[4].set_xlabel("iteration")
    ax[4].set_title("training loss")
    fig.tight_layout()
    png = os.path.join(args.out, "quickstart.png")
    fig.savefig(png, dpi=80)
    print(f"wrote {png}")
    if args.check and not (answer.best["id"] == object_id and iou >= 0.5):
        print(f"check failed: expected object {object_id} with mask IoU >= 0.5", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
