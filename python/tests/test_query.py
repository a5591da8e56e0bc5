"""hgs.query and hgs.evaluate: ranked objects, per-view masks, 3D selection and export, checked against the
command line (`hgs query`, `hgs eval`) on the same model."""

import json
import subprocess

import numpy as np
import pytest

import hgs


def phrase_of_an_object(scene):
    names = [n for n in scene.object_names.values() if n in scene.text_embeddings]
    assert names, "the synthetic scene names its objects in text_embeddings.json"
    return names[0]


def test_query_matches_the_command_line(hybrid_model, scene, scene_dir, hgs_binary, tmp_path):
    text = phrase_of_an_object(scene)
    r = hgs.query(hybrid_model, scene, text, views=[0, scene.views[3].name])
    assert r.text == text and len(r.objects) >= 1 and r.chosen == [r.best["id"]]
    rel = [o["relevancy"] for o in r.objects]
    cos = [o["cosine"] for o in r.objects]
    assert cos == sorted(cos, reverse=True)  # ranked by cosine (query/query.h), relevancy reported
    model_dir = tmp_path / "model"
    hybrid_model.save(str(model_dir))
    out = tmp_path / "q"
    subprocess.run([hgs_binary, "query", scene_dir, str(model_dir), "--text", text, "--split", "all", "--out",
                    str(out), "--quiet"], check=True, capture_output=True)
    with open(out / "result.json") as f:
        q = json.load(f)["queries"][0]
    assert [s["object"] for s in q["scores"]] == [o["id"] for o in r.objects]
    np.testing.assert_allclose([s["relevancy"] for s in q["scores"]], rel, rtol=1e-6)
    assert [c["object"] for c in q["chosen"]] == r.chosen
    # Masks: opacity > 0.5, with as many pixels as the command line's mask of that view.
    masks = r.masks
    assert list(masks) == [scene.views[0].name, scene.views[3].name]
    for name, mk in masks.items():
        assert mk.dtype == bool and mk.shape == (scene.views[0].height, scene.views[0].width)
        np.testing.assert_array_equal(mk, r.opacity(name) > 0.5)
        cli_pixels = next(v["mask_pixels"] for v in q["views"] if v["view"] == name)
        assert int(mk.sum()) == cli_pixels
    assert r.relevancy(0).shape == mk.shape


def test_selection_and_export(hybrid_model, scene, tmp_path):
    r = hgs.query(hybrid_model, scene, phrase_of_an_object(scene))
    sel, rest = r.select(), r.select(remove=True)
    assert sel.n > 0 and sel.n + rest.n == hybrid_model.n
    assert set(np.unique(sel.object_ids)) == set(r.chosen)
    assert not set(np.unique(rest.object_ids)) & set(r.chosen)
    path = r.export(str(tmp_path / "object.ply"))
    back = hgs.Model.load(path)
    np.testing.assert_array_equal(back.means, sel.means)
    # The selected object renders where the query's mask is.
    a = hgs.render(sel, scene, 0)["alpha"]
    mk = r.mask(0)
    if mk.sum() > 0:
        assert a[mk].mean() > a[~mk].mean()


def test_export_by_text_takes_the_answer_of_the_query(hybrid_model, scene, scene_dir, hgs_binary, tmp_path):
    # `hgs export --text` writes the Gaussians of every object the answer chooses (its anchor and fragments).
    text = phrase_of_an_object(scene)
    model_dir = tmp_path / "model"
    hybrid_model.save(str(model_dir))
    out = tmp_path / "by_text.ply"
    p = subprocess.run([hgs_binary, "export", str(model_dir), "--text", text, "--scene", scene_dir, "--out", str(out)],
                       check=True, capture_output=True, text=True)
    r = hgs.query(hybrid_model, scene, text)
    assert f"object {r.chosen[0]} (" in p.stdout
    np.testing.assert_array_equal(hgs.Model.load(str(out)).means, r.select().means)


def test_query_errors(hybrid_model, scene):
    with pytest.raises(hgs.Error, match="no such phrase|not in|text_embeddings"):
        hgs.query(hybrid_model, scene, "a phrase nobody embedded")
    with pytest.raises(hgs.Error, match="no view named"):
        hgs.query(hybrid_model, scene, phrase_of_an_object(scene), views=["nope"])


def test_evaluate_matches_the_command_line(hybrid_model, scene, scene_dir, hgs_binary, tmp_path):
    rep = hgs.evaluate(hybrid_model, scene, protocol="instances", mode="object")
    assert [r["mode"] for r in rep["reports"]] == ["object"]
    model_dir = tmp_path / "model"
    hybrid_model.save(str(model_dir))
    out = tmp_path / "report.json"
    subprocess.run([hgs_binary, "eval", scene_dir, str(model_dir), "--protocol", "instances", "--mode", "object",
                    "--out", str(out), "--no-png", "--quiet"], check=True, capture_output=True)
    with open(out) as f:
        cli = json.load(f)["reports"][0]
    py = rep["reports"][0]
    for key in ("protocol", "mode"):
        assert py[key] == cli[key]
    def untimed(records):  # every metric, without the timings
        return [{k: v for k, v in r.items() if k != "seconds"} for r in records]

    assert len(py["records"]) > 0
    assert untimed(py["records"]) == untimed(cli["records"])
    with pytest.raises(hgs.Error, match="unknown protocol 'nope'"):
        hgs.evaluate(hybrid_model, scene, protocol="nope")


def test_evaluate_protocol_variants(hybrid_model, scene):
    # The named scoring variants: the report names the variant; instances-scaled changes pixel mode only.
    base = hgs.evaluate(hybrid_model, scene, protocol="instances", mode="both")["reports"]
    scaled = hgs.evaluate(hybrid_model, scene, protocol="instances-scaled", mode="both")["reports"]
    assert [r["protocol"] for r in scaled] == ["instances-scaled"] * 3
    def untimed(records):
        return [{k: v for k, v in r.items() if k != "seconds"} for r in records]

    assert untimed(scaled[0]["records"]) == untimed(base[0]["records"])  # object mode
    assert "lerf_windows" in scaled[1]["extra"] and "lerf_windows" not in base[1]["extra"]
    # Pixel mode's default rule (hgs's object-embedding map) comes with the paper's language map beside it: the
    # report relevancy="lerf" gives on its own.
    assert [r["mode"] for r in base] == ["object", "pixel", "pixel-paper-map"]
    assert base[1]["extra"]["relevancy"] == "objects" and base[2]["extra"]["relevancy"] == "lerf"
    lerf = hgs.evaluate(hybrid_model, scene, protocol="instances", mode="pixel", relevancy="lerf")["reports"]
    assert [r["mode"] for r in lerf] == ["pixel"]
    assert len(lerf[0]["records"]) > 0
    assert untimed(lerf[0]["records"]) == untimed(base[2]["records"])
    assert lerf[0]["summary"]["mIoU"] == base[2]["summary"]["mIoU"]
    alone = hgs.evaluate(hybrid_model, scene, protocol="instances", mode="pixel", paper_map=False)["reports"]
    assert [r["mode"] for r in alone] == ["pixel"]
    labelled = hgs.evaluate(hybrid_model, scene, protocol="3d-ovs-labelled", mode="object")["reports"]
    assert labelled[0]["protocol"] == "3d-ovs-labelled"
    assert "miou_ceiling" not in labelled[0]["extra"]


def test_fragment_margin_and_query_sets(hybrid_model, scene):
    # fragment_margin=0: the best label alone; a large margin may only add labels, never drop the best one.
    name = phrase_of_an_object(scene)
    best = [o["id"] for o in hgs.query(hybrid_model, scene, name, fragment_margin=0).objects if o["chosen"]]
    wide = [o["id"] for o in hgs.query(hybrid_model, scene, name, fragment_margin=2.0).objects if o["chosen"]]
    assert len(best) == 1 and best[0] == wide[0] and set(best) <= set(wide)
    # The tiny scene is of the simple world: it has no query sets, and asking for one names the file.
    with pytest.raises(hgs.Error, match="queries.json"):
        hgs.evaluate(hybrid_model, scene, protocol="instances", mode="object", queries="synonyms")


def test_anchor_support(hybrid_model, scene):
    # The option reaches the C++ rule (query/session.h): on a model whose labels all render their objects the anchor
    # is the same with and without it; out of [0, 1] it is a one-line error naming the argument.
    name = phrase_of_an_object(scene)
    off = hgs.query(hybrid_model, scene, name, fragment_margin=0)
    on = hgs.query(hybrid_model, scene, name, fragment_margin=0, anchor_support=0.01)
    assert off.chosen == on.chosen
    report = hgs.evaluate(hybrid_model, scene, protocol="instances", mode="object", anchor_support=0.01)
    assert report["reports"][0]["mode"] == "object"
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(hgs.Error, match="anchor_support must be in"):
            hgs.query(hybrid_model, scene, name, anchor_support=bad)
