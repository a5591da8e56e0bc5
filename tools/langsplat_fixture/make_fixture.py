#!/usr/bin/env python3
"""Writes a LangSplat-format fixture (what LangSplat's preprocess.py leaves in language_features/) for a synthetic
hgs scene, so `hgs masks import SCENE --from langsplat OUT` can be tried without SAM, CLIP or a GPU.

For every view: OUT/<stem>_s.npy, float32 [4, H, W] (levels default, s, m, l), -1 = no mask, otherwise an index into
the concatenated mask list; OUT/<stem>_f.npy, float32 [M, D], one feature per mask. As in preprocess.py, level j's
indices are offset by the mask counts of levels 0..j-1. Masks come from the scene's exact instance maps
(gt/instances/): levels default and l hold the whole objects; levels s and m hold each object's left / right half
of its bounding box as two masks (a coarse stand-in for SAM's parts). Features are the objects' text embeddings from
text_embeddings.json (names from masks/objects.json). Python standard library only (no numpy).

Usage: tools/langsplat_fixture/make_fixture.py SCENE OUT
"""
import json
import os
import struct
import sys
import zlib


def read_grey_png(path):
    """8-bit greyscale, non-interlaced PNG -> (width, height, rows as bytearrays)."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path}: not a PNG")
    pos, idat, w = 8, b"", None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or ctype != 0 or interlace:
                sys.exit(f"{path}: expected an 8-bit greyscale non-interlaced PNG")
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    rows, prev = [], bytearray(w)
    for y in range(h):
        f, line = raw[y * (w + 1)], bytearray(raw[y * (w + 1) + 1:(y + 1) * (w + 1)])
        for x in range(w):
            a = line[x - 1] if x else 0
            b, c = prev[x], prev[x - 1] if x else 0
            if f == 1:
                line[x] = (line[x] + a) & 255
            elif f == 2:
                line[x] = (line[x] + b) & 255
            elif f == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, rows


def write_npy_f32(path, shape, values):
    header = "{'descr': '<f4', 'fortran_order': False, 'shape': (%s), }" % "".join(f"{s}, " for s in shape)
    header += " " * ((64 - (10 + len(header) + 1) % 64) % 64) + "\n"
    with open(path + ".tmp", "wb") as f:
        f.write(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode())
        f.write(struct.pack("<%df" % len(values), *values))
    os.replace(path + ".tmp", path)


def main():
    if len(sys.argv) != 3 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0 if len(sys.argv) == 2 else 2)
    scene, out = sys.argv[1], sys.argv[2]
    names = json.load(open(os.path.join(scene, "masks", "objects.json")))
    text = json.load(open(os.path.join(scene, "text_embeddings.json")))
    os.makedirs(out, exist_ok=True)
    gt_dir = os.path.join(scene, "gt", "instances")
    files = sorted(f for f in os.listdir(gt_dir) if f.endswith(".png"))
    for i, name in enumerate(files):
        w, h, rows = read_grey_png(os.path.join(gt_dir, name))
        ids = sorted({v for r in rows for v in r if v})
        seg = [-1.0] * (4 * h * w)
        feats, count = [], 0
        for level in range(4):
            for k in ids:
                emb = text[names[str(k)]]
                xs = [x for r in rows for x, v in enumerate(r) if v == k]
                mid = (min(xs) + max(xs) + 1) / 2
                parts = [None] if level in (0, 3) else [0, 1]
                for part in parts:
                    for y in range(h):
                        for x in range(w):
                            if rows[y][x] == k and (part is None or (x >= mid) == bool(part)):
                                seg[level * h * w + y * w + x] = float(count)
                    feats.extend(emb)
                    count += 1
        stem = name[:-4]
        write_npy_f32(os.path.join(out, stem + "_s.npy"), (4, h, w), seg)
        write_npy_f32(os.path.join(out, stem + "_f.npy"), (count, len(feats) // max(count, 1)), feats)
        print(f"\r{i + 1}/{len(files)} views", end="", file=sys.stderr)
    print(f"\nwrote {len(files)} views to {out}")


if __name__ == "__main__":
    main()
