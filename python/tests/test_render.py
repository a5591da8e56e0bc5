"""hgs.render: the dict of numpy arrays of one view (taken over from the renderer, no copy), its consistency
(object opacities add up to alpha, view by name = by index) and its options."""

import numpy as np
import pytest

import hgs

from conftest import SYNTH


def test_outputs(hybrid_model, scene):
    H, W = SYNTH["height"], SYNTH["width"]
    r = hgs.render(hybrid_model, scene, 1, language=True)
    assert set(r) == {"rgb", "alpha", "depth", "objects", "language"}
    assert r["rgb"].dtype == np.float32 and r["rgb"].shape == (H, W, 3)
    assert r["alpha"].shape == (H, W) and r["depth"].shape == (H, W)
    L = hybrid_model.object_probs.shape[1]
    assert r["objects"].shape == (H, W, L) and r["language"].shape == (H, W, 16)
    for a in r.values():  # each array owns nothing itself: it holds the renderer's vector (a capsule)
        assert not a.flags.owndata and a.base is not None
    assert 0 <= r["alpha"].min() and r["alpha"].max() <= 1 and r["alpha"].mean() > 0.5
    # sum_k A_k = sum_n (sum_k q_nk) alpha T = alpha, since every q row sums to 1.
    np.testing.assert_allclose(r["objects"].sum(axis=2), r["alpha"], atol=2e-3)
    # Expected depth: positive where something is rendered.
    assert (r["depth"][r["alpha"] > 0.5] > 0).all()


def test_view_by_name_and_background(hybrid_model, scene):
    v = scene.views[2]
    a = hgs.render(hybrid_model, scene, 2)
    b = hgs.render(hybrid_model, scene, v.name, depth=False, objects=False)
    np.testing.assert_array_equal(a["rgb"], b["rgb"])
    assert "depth" not in b and "objects" not in b and "language" not in b
    white = hgs.render(hybrid_model, scene, 2, background=1.0)["rgb"]
    # rgb = sum c alpha T + T_final * background: white - black = 1 - alpha.
    np.testing.assert_allclose(white - a["rgb"], np.repeat((1 - a["alpha"])[..., None], 3, axis=2), atol=1e-5)


def test_render_errors(hybrid_model, scene):
    with pytest.raises(hgs.Error, match="out of range"):
        hgs.render(hybrid_model, scene, 99)
    with pytest.raises(ValueError, match="background"):
        hgs.render(hybrid_model, scene, 0, background=(1, 0))


def test_near_plane(rgb_model, scene, tmp_path):
    # hgs.train sets the model's near_plane from its configuration; hgs.render culls at it unless told another,
    # and Model.load reads it from the config.json beside the PLY.
    assert rgb_model.near_plane == pytest.approx(0.01)
    a = hgs.render(rgb_model, scene, 1)
    assert a["alpha"].max() > 0.5
    far = hgs.render(rgb_model, scene, 1, near_plane=100.0)  # the cameras are about 1 unit from the scene
    assert far["alpha"].max() == 0
    m = hgs.train(scene, method="rgb", iters=40, progress=False, near_plane=100.0, out=tmp_path / "m")
    assert m.near_plane == pytest.approx(100.0)
    assert hgs.render(m, scene, 1)["alpha"].max() == 0
    assert m.copy().near_plane == pytest.approx(100.0)  # a copy is seen from the same cameras
    assert hgs.render(m.copy(), scene, 1)["alpha"].max() == 0
    loaded = hgs.Model.load(tmp_path / "m")
    assert loaded.near_plane == pytest.approx(100.0)
    np.testing.assert_array_equal(hgs.render(loaded, scene, 1, near_plane=0.01)["rgb"],
                                  hgs.render(m, scene, 1, near_plane=0.01)["rgb"])
    with pytest.raises(hgs.Error, match="near"):
        hgs.render(rgb_model, scene, 1, near_plane=-1.0)


def test_select_keeps_the_near_plane(hybrid_model):
    m = hybrid_model.copy()
    m.near_plane = 0.5
    assert m.select([1]).near_plane == pytest.approx(0.5)
    assert m.select([1], remove=True).near_plane == pytest.approx(0.5)
    assert hgs.Model(m.means, m.log_scales, m.rotations, m.opacity_logits, m.sh).near_plane == pytest.approx(0.01)
