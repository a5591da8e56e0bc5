"""hgs.Model: numpy views on the model's storage (zero copy, writable), PLY round trips, construction from
arrays with checked dtypes and shapes, hybrid fields and the errors of a model of the other method."""

import numpy as np
import pytest

import hgs


def test_arrays_are_views_on_the_model(hybrid_model):
    m = hybrid_model.copy()
    n = m.n
    assert len(m) == n > 0 and m.is_hybrid and m.method == "hybrid"
    shapes = {"means": (n, 3), "log_scales": (n, 3), "rotations": (n, 4), "opacity_logits": (n,),
              "sh": (n, (m.sh_degree + 1) ** 2, 3)}
    for name, shape in shapes.items():
        a = getattr(m, name)
        assert a.dtype == np.float32 and a.shape == shape, name
        assert a.base is m, f"{name}: the array's base must be the model (no copy)"
        assert not a.flags.owndata and a.flags.writeable
        # Two reads share one buffer: the model's own storage.
        assert getattr(m, name).__array_interface__["data"][0] == a.__array_interface__["data"][0]
    L = m.object_probs.shape[1]
    assert m.object_probs.base is m and m.object_probs.shape == (n, L) and L == 4  # 3 objects + background
    np.testing.assert_allclose(m.object_probs.sum(axis=1), 1, atol=1e-4)
    lang = m.language
    assert lang.base is m and lang.dtype == np.float16 and lang.shape == (n, 16)  # half storage, as trained
    ids = m.object_ids
    assert ids.dtype == np.int32 and ids.shape == (n,) and ids.min() >= 0 and ids.max() < L
    np.testing.assert_array_equal(ids, np.argmax(m.object_probs, axis=1))
    assert set(m.extras) >= {"obj", "obj_id", "lang"}


def test_writing_through_a_view_changes_the_model(hybrid_model, scene, tmp_path):
    m = hybrid_model.copy()
    before = hgs.render(m, scene, 0)["alpha"].sum()
    assert before > 1
    m.opacity_logits[:] = -30.0  # every Gaussian transparent
    np.testing.assert_allclose(m.opacities, 0, atol=1e-9)
    assert hgs.render(m, scene, 0)["alpha"].max() < 1e-6
    m.means[0] = (1.5, -2.0, 3.25)
    m.language[1, :] = 0.5
    path = m.save(str(tmp_path / "edited.ply"))
    back = hgs.Model.load(path)
    np.testing.assert_array_equal(back.means[0], [1.5, -2.0, 3.25])
    np.testing.assert_array_equal(back.opacity_logits, -30.0)
    np.testing.assert_array_equal(back.language[1], 0.5)
    # The original model is untouched (copy() is deep).
    assert hgs.render(hybrid_model, scene, 0)["alpha"].sum() == pytest.approx(before)


def test_views_keep_the_model_alive(hybrid_model):
    means = hybrid_model.copy().means  # the copy is referenced by the array only
    expected = hybrid_model.means
    import gc
    gc.collect()
    np.testing.assert_array_equal(means, expected)


def test_ply_round_trip(hybrid_model, rgb_model, tmp_path):
    for m in (hybrid_model, rgb_model):
        folder = tmp_path / m.method
        path = m.save(str(folder))
        assert path.endswith("point_cloud.ply")
        back = hgs.Model.load(str(folder))
        assert back.n == m.n and back.sh_degree == m.sh_degree and back.method == m.method
        for name in ("means", "log_scales", "rotations", "opacity_logits", "sh"):
            np.testing.assert_array_equal(getattr(back, name), getattr(m, name), err_msg=name)
        assert set(back.extras) == set(m.extras)
        for k, v in m.extras.items():  # files hold float32: half values come back exactly
            np.testing.assert_array_equal(back.extras[k], v.astype(np.float32), err_msg=k)
    # A model folder has its config.json: the near plane a saved model is rendered at comes back with it.
    m = rgb_model.copy()
    m.near_plane = 0.25
    m.save(str(tmp_path / "near"))
    assert (tmp_path / "near" / "config.json").exists()
    assert hgs.Model.load(str(tmp_path / "near")).near_plane == 0.25


def test_model_from_arrays(tmp_path):
    rng = np.random.default_rng(0)
    n = 50
    arrays = dict(means=rng.normal(size=(n, 3)).astype(np.float32),
                  log_scales=np.full((n, 3), -3, np.float32),
                  rotations=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                  opacity_logits=np.zeros(n, np.float32),
                  sh=rng.normal(size=(n, 4, 3)).astype(np.float32))
    m = hgs.Model(**arrays, extras={"tag": np.arange(n, dtype=np.float32)[:, None]})
    assert m.n == n and m.sh_degree == 1 and m.method == "rgb"
    for k, v in arrays.items():
        np.testing.assert_array_equal(getattr(m, k), v)
    back = hgs.Model.load(m.save(str(tmp_path / "m.ply")))
    np.testing.assert_array_equal(back.sh, arrays["sh"])
    np.testing.assert_array_equal(back.extras["tag"], np.arange(n, dtype=np.float32))
    # Wrong dtype, wrong shape, not an array: clear exceptions, no conversion.
    with pytest.raises(TypeError, match="means: expected dtype float32, got float64"):
        hgs.Model(**{**arrays, "means": arrays["means"].astype(np.float64)})
    with pytest.raises(ValueError, match=r"rotations: expected shape \[50, 4\], got \[50, 3\]"):
        hgs.Model(**{**arrays, "rotations": arrays["rotations"][:, :3].copy()})
    with pytest.raises(ValueError, match="sh: 5 coefficients"):
        hgs.Model(**{**arrays, "sh": np.zeros((n, 5, 3), np.float32)})
    with pytest.raises(TypeError, match="numpy array"):
        hgs.Model(**{**arrays, "opacity_logits": [0.0] * n})


def test_model_of_another_method(rgb_model, scene):
    assert rgb_model.method == "rgb" and not rgb_model.is_hybrid
    with pytest.raises(hgs.Error, match="not a hybrid model"):
        rgb_model.object_probs
    with pytest.raises(hgs.Error, match="hybrid"):
        hgs.query(rgb_model, scene, "anything")
    with pytest.raises(hgs.Error, match="hybrid"):
        hgs.render(rgb_model, scene, 0, language=True)
    with pytest.raises(hgs.Error, match="hybrid"):
        rgb_model.select([1])


def test_missing_file(tmp_path):
    with pytest.raises(hgs.Error) as e:
        hgs.Model.load(str(tmp_path / "none.ply"))
    assert "none.ply" in str(e.value)
