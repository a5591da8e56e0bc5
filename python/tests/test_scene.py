"""hgs.Scene and hgs.View: metadata, poses and intrinsics as numpy, per-view pixels, errors for bad input."""

import json
import os

import matplotlib.image
import numpy as np
import pytest

import hgs

from conftest import SYNTH


def test_views_and_intrinsics(scene):
    assert len(scene) == SYNTH["views"] == len(scene.views)
    assert sorted(scene.train_indices + scene.test_indices) == list(range(len(scene)))
    v = scene.views[0]
    assert (v.width, v.height) == (SYNTH["width"], SYNTH["height"]) == v.size
    assert v.K.dtype == np.float64 and v.K.shape == (3, 3)
    np.testing.assert_array_equal(v.K, [[v.fx, 0, v.cx], [0, v.fy, v.cy], [0, 0, 1]])
    # The pose is a rigid transform whose inverse maps the origin of the camera to its centre.
    assert v.R.shape == (3, 3) and v.t.shape == (3,) and v.pose.shape == (4, 4)
    np.testing.assert_allclose(v.R @ v.R.T, np.eye(3), atol=1e-9)
    np.testing.assert_array_equal(v.pose[:3, :3], v.R)
    np.testing.assert_array_equal(v.pose[:3, 3], v.t)
    np.testing.assert_allclose(v.R @ v.camera_center + v.t, 0, atol=1e-9)
    assert scene.view(v.name).index == 0 and scene.view(v.stem).index == 0 and scene.index(-1) == len(scene) - 1
    assert scene.index(np.int64(3)) == 3  # numpy integers are indices too


def test_image_matches_the_png_on_disk(scene):
    for i in (0, len(scene) - 1):
        img = scene.image(i)
        assert img.dtype == np.uint8 and img.shape == (SYNTH["height"], SYNTH["width"], 3)
        ref = matplotlib.image.imread(scene.views[i].image_path)[..., :3]  # float in [0, 1]
        np.testing.assert_array_equal(img, np.round(ref * 255).astype(np.uint8))


def test_masks_features_and_text_embeddings(scene, scene_dir):
    m = scene.mask(0)
    assert m.dtype == np.int32 and m.shape == (SYNTH["height"], SYNTH["width"])
    assert 0 <= m.min() and m.max() <= SYNTH["objects"] and m.max() > 0
    assert scene.num_objects == SYNTH["objects"]
    f = scene.features(0)
    assert f.dtype == np.float32 and f.shape == (SYNTH["height"], SYNTH["width"], SYNTH["feature_dim"])
    g = scene.features(0, upsample=False)
    assert g.shape[2] == SYNTH["feature_dim"] and g.shape[0] < SYNTH["height"]
    np.testing.assert_array_equal(g, np.load(os.path.join(scene_dir, "features", scene.views[0].stem + ".npy")))
    with open(os.path.join(scene_dir, "text_embeddings.json")) as fh:
        on_disk = json.load(fh)
    te = scene.text_embeddings
    assert len(te) > 0
    for phrase, e in te.items():
        assert e.dtype == np.float32 and e.shape == (SYNTH["feature_dim"],)
    assert set(scene.object_names.values()) <= set(te) | set(on_disk.get("embeddings", on_disk))
    pts, cols = scene.points, scene.point_colors
    assert pts.shape == (SYNTH["points"], 3) == cols.shape and cols.min() >= 0 and cols.max() <= 1


def test_bad_input(scene, tmp_path):
    missing = str(tmp_path / "no_such_scene")
    with pytest.raises(hgs.Error) as e:
        hgs.Scene.load(missing)
    assert missing in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(hgs.Error, match="downscale"):
        hgs.Scene.load(missing, downscale=0)
    with pytest.raises(hgs.Error, match="out of range"):
        scene.image(len(scene))
    with pytest.raises(hgs.Error, match="no view named 'nope'"):
        scene.view("nope")
    with pytest.raises(TypeError):
        scene.image(1.5)


def test_downscale(scene_dir):
    s2 = hgs.Scene.load(scene_dir, downscale=2)
    assert s2.downscale == 2 and s2.views[0].size == (SYNTH["width"] // 2, SYNTH["height"] // 2)
    assert s2.image(0).shape == (SYNTH["height"] // 2, SYNTH["width"] // 2, 3)


def test_synth_default_world_is_the_realistic_one(tmp_path):
    # hgs.synth's default world is `hgs synth`'s: realistic, with query sets and surfaces cut into tracked pieces.
    opts = {k: v for k, v in SYNTH.items() if k not in ("world", "objects_only")}
    out = hgs.synth(str(tmp_path / "realistic"), **opts)
    with open(os.path.join(out, "synth.json")) as f:
        assert json.load(f)["world"] == "realistic"
    with open(os.path.join(out, "gt", "queries.json")) as f:
        queries = json.load(f)
    assert len(queries["names"]) == SYNTH["objects"] and len(queries["synonyms"]) == SYNTH["objects"]
    with open(os.path.join(out, "masks", "objects.json")) as f:
        names = json.load(f)
    assert "wooden table (piece 1)" in names.values()
    with pytest.raises(Exception, match="--world"):
        hgs.synth(str(tmp_path / "bad"), world="fancy", **opts)


def test_synth_simple_world_has_surfaces_and_parts(tmp_path):
    # The simple world with its SAM-like defaults: the background surfaces are mask objects after the objects, and a
    # split object's part follows them; objects_only=True gives the masks of the objects alone.
    opts = dict(SYNTH, objects_only=False, split_rate=1.0)
    out = hgs.synth(str(tmp_path / "sam_like"), **opts)
    with open(os.path.join(out, "masks", "objects.json")) as f:
        names = json.load(f)
    assert names["4"] == "wooden table" and names["5"] == "floor"
    assert sorted(names[k] for k in names if int(k) > 5) == sorted(names[str(k)] + " (part)" for k in (1, 2, 3))
    m = hgs.Scene.load(out).mask(0)
    assert m.max() > 5  # a part is in view 0
