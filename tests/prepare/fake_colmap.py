#!/usr/bin/env -S python3 -S
# A stand-in for Debian's `colmap` in the tests of `hgs prepare` (given with --colmap): the four subcommands the
# pose stages run, in milliseconds, with the files COLMAP would write (database.db with the images / keypoints /
# descriptors tables, WORK/sparse/0/*.bin, the undistorted images and model). Every image registers, with one
# camera per image size. fake_colmap.json next to this script (optional) makes it misbehave, as a full disk or a
# hard capture does:
#   "drop_last_feature": true  feature_extractor leaves the last image of its list out of the database, logs
#                              COLMAP's "database or disk is full" and still exits 0
#   "sleep_in": "<sub>"        that subcommand writes its pid to `pid` next to this script and sleeps 60 s
#   "register": K              the mapper registers only the first K images (by name)
#   "robust_register": K       ... but K when run with the wide-baseline options (--Mapper.init_min_num_inliers)
#   "affine_register": K       ... and K when besides the database holds affine features (estimate_affine_shape)
# Every call is appended to calls.log next to this script (the subcommand and its arguments, one line).
import json
import os
import shutil
import sqlite3
import struct
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def config():
    try:
        with open(os.path.join(HERE, "fake_colmap.json")) as f:
            return json.load(f)
    except FileNotFoundError:
        return {}


def arg(args, name, default=None):
    return args[args.index(name) + 1] if name in args else default


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:4] == b"\x89PNG":
        return struct.unpack(">II", head[16:24])
    return 64, 48


def feature_extractor(args, cfg):
    db = sqlite3.connect(arg(args, "--database_path"))
    db.execute("CREATE TABLE IF NOT EXISTS cameras (camera_id INTEGER PRIMARY KEY, width INTEGER, height INTEGER)")
    db.execute("CREATE TABLE IF NOT EXISTS images (image_id INTEGER PRIMARY KEY, name TEXT UNIQUE, camera_id INTEGER)")
    db.execute("CREATE TABLE IF NOT EXISTS keypoints (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB)")
    db.execute("CREATE TABLE IF NOT EXISTS descriptors (image_id INTEGER PRIMARY KEY, rows INTEGER, cols INTEGER, data BLOB)")
    db.execute("CREATE TABLE IF NOT EXISTS fake_settings (name TEXT)")
    if arg(args, "--SiftExtraction.estimate_affine_shape") == "1":
        db.execute("INSERT INTO fake_settings VALUES ('affine')")
    with open(arg(args, "--image_list_path")) as f:
        names = [line.rstrip("\n") for line in f if line.strip()]
    if cfg.get("drop_last_feature"):
        names = names[:-1]
    w, h = png_size(os.path.join(arg(args, "--image_path"), names[0]))
    cam = db.execute("INSERT INTO cameras (width, height) VALUES (?, ?)", (w, h)).lastrowid
    for i, n in enumerate(names):
        image = db.execute("INSERT INTO images (name, camera_id) VALUES (?, ?)", (n, cam)).lastrowid
        db.execute("INSERT INTO keypoints VALUES (?, 10, 6, ?)", (image, b"\0" * 240))
        db.execute("INSERT INTO descriptors VALUES (?, 10, 128, ?)", (image, b"\0" * 1280))
        print(f"Processed file [{i + 1}/{len(names)}]", flush=True)
    db.commit()
    if cfg.get("drop_last_feature"):
        print("SQLite error [database.cc, line 1090]: database or disk is full", flush=True)


def write_model(out, cameras, images):
    """cameras: {id: (w, h)}; images: [(id, name, camera_id)]"""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "cameras.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(cameras)))
        for cid, (w, h) in sorted(cameras.items()):
            f.write(struct.pack("<iiQQ3d", cid, 0, w, h, float(max(w, h)), w / 2, h / 2))  # SIMPLE_PINHOLE
    with open(os.path.join(out, "images.bin"), "wb") as f:
        f.write(struct.pack("<Q", len(images)))
        for k, (iid, name, cid) in enumerate(images):
            f.write(struct.pack("<i4d3di", iid, 1, 0, 0, 0, 0.1 * k, 0, 4, cid))
            f.write(name.encode() + b"\0")
            f.write(struct.pack("<Q", 1))
            f.write(struct.pack("<ddq", 1.0, 1.0, 1))
    with open(os.path.join(out, "points3D.bin"), "wb") as f:
        f.write(struct.pack("<Q", 1))
        f.write(struct.pack("<Q3d3Bd", 1, 0, 0, 0, 128, 128, 128, 0.5))
        f.write(struct.pack("<Q", len(images)))
        for iid, _, _ in images:
            f.write(struct.pack("<ii", iid, 0))


def mapper(args, cfg):
    db = sqlite3.connect(arg(args, "--database_path"))
    cameras = {cid: (w, h) for cid, w, h in db.execute("SELECT camera_id, width, height FROM cameras")}
    images = sorted(db.execute("SELECT image_id, name, camera_id FROM images"), key=lambda r: r[1])
    k = cfg.get("register", len(images))
    if "--Mapper.init_min_num_inliers" in args:
        k = cfg.get("robust_register", k)
        if list(db.execute("SELECT name FROM fake_settings WHERE name = 'affine'")):
            k = cfg.get("affine_register", k)
    images = images[:k]
    for i, (iid, _, _) in enumerate(images):
        print(f"Registering image #{iid} ({i + 1})", flush=True)
    if len(images) < 3:
        print("=> failed to create sparse model", flush=True)
        return
    write_model(os.path.join(arg(args, "--output_path"), "0"), cameras, images)


def image_undistorter(args, cfg):
    model, out = arg(args, "--input_path"), arg(args, "--output_path")
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    os.makedirs(os.path.join(out, "sparse"), exist_ok=True)
    with open(os.path.join(model, "images.bin"), "rb") as f:
        data = f.read()
    n, at, names = struct.unpack_from("<Q", data)[0], 8, []
    for _ in range(n):
        at += 4 + 56 + 4
        end = data.index(b"\0", at)
        names.append(data[at:end].decode())
        at = end + 1
        at += 8 + 24 * struct.unpack_from("<Q", data, at)[0]
    for i, name in enumerate(names):
        shutil.copy(os.path.join(arg(args, "--image_path"), name), os.path.join(out, "images", name))
        print(f"Undistorting image [{i + 1}/{len(names)}]", flush=True)
    for f in ("cameras.bin", "images.bin", "points3D.bin"):
        shutil.copy(os.path.join(model, f), os.path.join(out, "sparse", f))


def main():
    sub, args = sys.argv[1], sys.argv[2:]
    cfg = config()
    with open(os.path.join(HERE, "calls.log"), "a") as f:
        f.write(" ".join(sys.argv[1:]) + "\n")
    if cfg.get("sleep_in") == sub:
        with open(os.path.join(HERE, "pid.tmp"), "w") as f:
            f.write(str(os.getpid()))
        os.rename(os.path.join(HERE, "pid.tmp"), os.path.join(HERE, "pid"))
        time.sleep(60)
    if sub == "feature_extractor":
        feature_extractor(args, cfg)
    elif sub in ("exhaustive_matcher", "sequential_matcher", "vocab_tree_matcher"):
        print("Matching image [1/1]", flush=True)
    elif sub == "mapper":
        mapper(args, cfg)
    elif sub == "image_undistorter":
        image_undistorter(args, cfg)
    else:
        print(f"fake colmap: unknown subcommand {sub}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
