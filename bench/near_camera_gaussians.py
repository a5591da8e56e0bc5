#!/usr/bin/env python3
"""Gaussians close to one camera with footprints larger than its image (floaters in front of a held-out view).

    python3 bench/near_camera_gaussians.py SCENE MODEL VIEW [--near 0.1] [--wide 0.25] [--out MODEL_WITHOUT]

SCENE is a COLMAP scene (sparse/0/{cameras,images}.bin, PINHOLE or SIMPLE_PINHOLE), MODEL an hgs model folder
(point_cloud.ply, 3DGS layout), VIEW an image name of the scene (e.g. 0025.jpg). Lists the Gaussians whose centre is
in front of VIEW's camera nearer than --near x the view's median depth (the median over the Gaussian centres inside
its frustum) and whose 3-sigma footprint (3 fx max(scale) / depth pixels) is wider than --wide x the image width,
with the training cameras they are also in front of. With --out, writes a copy of MODEL without them, to be
rendered with `hgs render SCENE MODEL_WITHOUT` beside the original (docs/scaling.md, kumamon seed 3).
Written here because no packaged tool reads both COLMAP binaries and a 3DGS PLY; numpy only.
"""
import argparse
import os
import shutil
import struct

import numpy as np


def read_images(path):  # COLMAP images.bin: name -> (qvec wxyz, tvec, camera id)
    out = {}
    with open(path, "rb") as f:
        for _ in range(struct.unpack("<Q", f.read(8))[0]):
            _, qw, qx, qy, qz, tx, ty, tz, cid = struct.unpack("<idddddddi", f.read(64))
            name = b""
            while (c := f.read(1)) != b"\0":
                name += c
            f.read(24 * struct.unpack("<Q", f.read(8))[0])  # the 2D points
            out[name.decode()] = (np.array([qw, qx, qy, qz]), np.array([tx, ty, tz]), cid)
    return out


def read_cameras(path):  # COLMAP cameras.bin, pinhole models: id -> (width, height, fx, fy, cx, cy)
    nparams = {0: 3, 1: 4}  # SIMPLE_PINHOLE, PINHOLE
    out = {}
    with open(path, "rb") as f:
        for _ in range(struct.unpack("<Q", f.read(8))[0]):
            cid, model, w, h = struct.unpack("<iiQQ", f.read(24))
            if model not in nparams:
                raise SystemExit(f"{path}: camera {cid} has model {model}; only PINHOLE and SIMPLE_PINHOLE are read")
            p = struct.unpack(f"<{nparams[model]}d", f.read(8 * nparams[model]))
            out[cid] = (w, h, p[0], p[1], p[2], p[3]) if model == 1 else (w, h, p[0], p[0], p[1], p[2])
    return out


def rotation(q):  # COLMAP world -> camera rotation from (w, x, y, z)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def read_ply(path):  # binary little-endian float vertices: header text, property names, [N, P] array
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    props = [line.split()[-1] for line in header.splitlines() if line.startswith("property")]
    n = int(next(line for line in header.splitlines() if line.startswith("element vertex")).split()[-1])
    return header, props, np.frombuffer(data[end:], dtype="<f4", count=n * len(props)).reshape(n, len(props))


def project(images, cameras, name, xyz):  # depth [N], u [N], v [N], (w, h, fx)
    q, t, cid = images[name]
    w, h, fx, fy, cx, cy = cameras[cid]
    p = xyz @ rotation(q).T + t
    z = p[:, 2]
    iz = 1 / np.where(z > 1e-9, z, 1e-9)
    return z, fx * p[:, 0] * iz + cx, fy * p[:, 1] * iz + cy, (w, h, fx)


def near_and_over(z, u, v, radius, w, h, depth_limit):  # [N]: nearer than depth_limit, footprint on the image
    return (z > 0) & (z < depth_limit) & (u > -radius) & (u < w + radius) & (v > -radius) & (v < h + radius)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene")
    ap.add_argument("model")
    ap.add_argument("view")
    ap.add_argument("--near", type=float, default=0.1, help="depth below this x the view's median depth")
    ap.add_argument("--wide", type=float, default=0.25, help="3-sigma radius above this x the image width")
    ap.add_argument("--out", help="write MODEL without the Gaussians found into this folder")
    a = ap.parse_args()
    sparse = os.path.join(a.scene, "sparse", "0")
    for f in (os.path.join(sparse, "images.bin"), os.path.join(sparse, "cameras.bin"),
              os.path.join(a.model, "point_cloud.ply")):
        if not os.path.isfile(f):
            raise SystemExit(f"{f}: not found")
    images, cameras = read_images(os.path.join(sparse, "images.bin")), read_cameras(os.path.join(sparse, "cameras.bin"))
    if a.view not in images:
        raise SystemExit(f"{sparse}/images.bin: no image named {a.view}")
    header, props, g = read_ply(os.path.join(a.model, "point_cloud.ply"))
    xyz = g[:, :3].astype(np.float64)
    scale = np.exp(g[:, [props.index(f"scale_{i}") for i in range(3)]].astype(np.float64)).max(1)
    opacity = 1 / (1 + np.exp(-g[:, props.index("opacity")].astype(np.float64)))

    z, u, v, (w, h, fx) = project(images, cameras, a.view, xyz)
    inside = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    median = np.median(z[inside])
    radius = 3 * fx * scale / np.where(z > 1e-9, z, 1e-9)
    found = near_and_over(z, u, v, radius, w, h, a.near * median) & (radius > a.wide * w)
    print(f"{a.view}: {inside.sum()} of {len(g)} Gaussian centres in view, median depth {median:.3f}; "
          f"{found.sum()} nearer than {a.near} x that with a 3-sigma radius above {a.wide} x {w} px")
    for i in np.where(found)[0]:
        near_others = []
        for other in sorted(images):
            if other == a.view:
                continue
            zo, uo, vo, (wo, ho, fxo) = project(images, cameras, other, xyz[i:i + 1])
            ro = 3 * fxo * scale[i:i + 1] / np.where(zo > 1e-9, zo, 1e-9)
            if near_and_over(zo, uo, vo, ro, wo, ho, a.near * median)[0]:
                near_others.append(f"{other} ({zo[0] / median:.3f})")
        print(f"  #{i}: depth {z[i] / median:.3f} x median, radius {radius[i]:.0f} px, opacity {opacity[i]:.3f}, "
              f"centre ({u[i]:.0f}, {v[i]:.0f}) px; as near to: {', '.join(near_others) or 'no other camera'}")
    if a.out:
        os.makedirs(a.out, exist_ok=True)
        for f in os.listdir(a.model):
            if f.endswith(".json"):
                shutil.copy(os.path.join(a.model, f), a.out)
        keep = g[~found]
        body = header.replace(f"element vertex {len(g)}", f"element vertex {len(keep)}").encode()
        tmp = os.path.join(a.out, "point_cloud.ply.tmp")
        with open(tmp, "wb") as f:
            f.write(body + keep.astype("<f4").tobytes())
        os.replace(tmp, os.path.join(a.out, "point_cloud.ply"))
        print(f"{a.out}/point_cloud.ply: {len(keep)} Gaussians")


if __name__ == "__main__":
    main()
