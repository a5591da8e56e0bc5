"""Hostile-but-realistic use of the package (issue 60): models that could not be loaded again are not saved, a model
folder is written whole or not at all, errors name the argument and its expected type, and echoed user text is
cut short."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import hgs

PY = os.path.dirname(os.path.dirname(os.path.abspath(hgs.__file__)))


@pytest.mark.parametrize("array,index,value,named", [
    ("means", (3, 1), np.nan, "means holds 1 NaN or infinite value (the first at Gaussian 3)"),
    ("log_scales", (0, 0), np.inf, "log_scales holds 1"),
    ("rotations", (5, 2), -np.inf, "rotations holds 1"),
    ("opacity_logits", (7,), np.nan, "opacity_logits holds 1 NaN or infinite value (the first at Gaussian 7)"),
    ("sh", (2, 0, 1), np.nan, "sh holds 1"),
    ("language", (4, 0), np.inf, "extras['lang'] holds 1 NaN or infinite value (the first at Gaussian 4)"),
    ("object_probs", (1, 1), np.nan, "extras['obj'] holds 1"),
])
def test_save_refuses_non_finite_arrays(hybrid_model, tmp_path, array, index, value, named):
    m = hybrid_model.copy()
    getattr(m, array)[index] = value
    for target in (tmp_path / "m.ply", tmp_path / "folder"):
        with pytest.raises(hgs.Error) as e:
            m.save(str(target))
        msg = str(e.value)
        assert named in msg and str(target) in msg and "\n" not in msg, msg
        assert not target.exists()
    assert os.listdir(tmp_path) == []


def test_save_into_a_folder_keeps_its_other_files(hybrid_model, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "config.json").write_text('{"near_plane": 0.2}\n')
    (out / "notes.txt").write_text("mine\n")
    hybrid_model.save(str(out))
    assert sorted(os.listdir(out)) == ["config.json", "notes.txt", "point_cloud.ply"]
    assert (out / "notes.txt").read_text() == "mine\n"
    assert hgs.Model.load(str(out)).near_plane == pytest.approx(0.2)
    assert sorted(os.listdir(tmp_path)) == ["out"]  # no temporary folder left beside it


def test_save_into_the_current_folder(hybrid_model, tmp_path, monkeypatch):
    # The folder is replaced as a whole: the process working in it moves to the new one.
    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.chdir(out)
    hybrid_model.save(".")
    hybrid_model.save(".")
    assert sorted(os.listdir(".")) == ["config.json", "point_cloud.ply"]
    assert hgs.Model.load(".").n == hybrid_model.n and os.path.samefile(os.getcwd(), out)


SAVE_LOOP = r"""
import sys
import hgs
m = hgs.Model.load(sys.argv[1])
out = sys.argv[2]
print("ready", flush=True)
for k in range(100000):
    m.save(f"{out}/m{k}")
"""


def test_model_folder_is_whole_when_the_saver_is_killed(hybrid_model, tmp_path):
    # A second Ctrl-C (or any kill) while a model folder was written left point_cloud.ply without config.json.
    # SIGKILL a process saving model folders in a loop at several moments: every folder there is complete.
    src = tmp_path / "src.ply"
    hybrid_model.save(str(src))
    env = dict(os.environ, PYTHONPATH=PY + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for i, delay in enumerate([0.05, 0.13, 0.21, 0.34, 0.55, 0.8]):
        out = tmp_path / f"run{i}"
        out.mkdir()
        p = subprocess.Popen([sys.executable, "-c", SAVE_LOOP, str(src), str(out)], stdout=subprocess.PIPE, env=env)
        assert p.stdout.readline().strip() == b"ready"
        time.sleep(delay)
        p.send_signal(signal.SIGKILL)
        p.wait()
        for name in os.listdir(out):
            if name.startswith("."):  # a temporary folder of the killed write: never a model's name
                assert name.endswith(".hgs-new") or name.endswith(".hgs-old"), name
                continue
            assert sorted(os.listdir(out / name)) == ["config.json", "point_cloud.ply"], (delay, name)
            assert hgs.Model.load(str(out / name)).n == hybrid_model.n


def test_training_output_is_whole_or_not_at_all(scene, tmp_path):
    out = tmp_path / "out"
    (out / "train_stats.json").mkdir(parents=True)  # cannot be replaced: the final write fails part way
    with pytest.raises(hgs.Error, match="train_stats.json"):
        hgs.train(scene, out=str(out), method="rgb", iters=4, progress=False, densify=False)
    assert sorted(os.listdir(out)) == ["config.json", "train_stats.json"]  # no point_cloud.ply alone
    assert sorted(os.listdir(tmp_path)) == ["out"]


def test_long_query_text_is_cut_in_errors(hybrid_model, scene):
    text = "teal flower pot " * 62500  # 1,000,000 characters, not a known phrase
    with pytest.raises(hgs.Error) as e:
        hgs.query(hybrid_model, scene, text)
    msg = str(e.value)
    assert len(msg) < 400 and "… (1000000 characters)" in msg and "\n" not in msg, msg[:500]
    with pytest.raises(hgs.Error) as e:
        scene.index("v" * 5000)
    assert len(str(e.value)) < 400 and "(5000 characters)" in str(e.value)
    with pytest.raises(hgs.Error) as e:
        hgs.train(scene, iters=1, progress=False, **{"k" * 3000: 1})
    assert "(3000 characters)" in str(e.value) and len(str(e.value).split("(options:")[0]) < 300


def test_long_query_text_is_cut_in_command_line_errors(hybrid_model, scene_dir, hgs_binary, tmp_path):
    hybrid_model.save(str(tmp_path / "m"))
    text = "q" * 100000
    r = subprocess.run([hgs_binary, "query", scene_dir, str(tmp_path / "m"), "--text", text, "--out", str(tmp_path / "q"),
                        "--quiet"],
                       capture_output=True, text=True)
    assert r.returncode == 1
    assert len(r.stderr) < 400 and "(100000 characters)" in r.stderr and r.stderr.count("\n") == 1, r.stderr[:500]


def type_error(call):
    with pytest.raises(TypeError) as e:
        call()
    return str(e.value)


def test_wrong_argument_types_name_the_argument(hybrid_model, scene):
    cases = [
        (lambda: hgs.render("model.ply", scene, 0), "render: model must be an hgs.Model, got str"),
        (lambda: hgs.render(hybrid_model, "scene", 0), "render: scene must be an hgs.Scene, got str"),
        (lambda: hgs.render(hybrid_model, scene, 1.5), "view: expected an index (int) or a name (str)"),
        (lambda: hgs.render(hybrid_model, scene, 0, near_plane="x"), "render: near_plane must be a number, got str"),
        (lambda: hgs.render(hybrid_model, scene, 0, background=["a", "b", "c"]),
         "render: background must be 3 numbers (RGB in [0, 1]) or one, got list"),
        (lambda: hgs.render(hybrid_model, scene, 0, sh_degree="2"), "render: sh_degree must be an int, got str"),
        (lambda: hgs.QuerySession(scene, "model"), "QuerySession: model must be an hgs.Model, got str"),
        (lambda: hgs.QuerySession("scene", hybrid_model), "QuerySession: scene must be an hgs.Scene, got str"),
        (lambda: hgs.Trainer("scene"), "Trainer: scene must be an hgs.Scene, got str"),
        (lambda: hgs.Trainer(scene, "rgb", "10"), "Trainer: iters must be an int, got str"),
        (lambda: hgs.Trainer(scene, "rgb", 10, {1: 2}), "Trainer: options keys must be str, got int"),
        (lambda: hgs.Model(np.zeros((2, 3), np.float32), np.zeros((2, 3), np.float32), np.zeros((2, 4), np.float32),
                           np.zeros(2, np.float32), np.zeros((2, 1, 3), np.float32), {1: np.zeros((2, 1), np.float32)}),
         "Model: extras keys must be str, got int"),
    ]
    for call, want in cases:
        msg = type_error(call)
        assert msg.startswith(want) and "\n" not in msg and "Unable to cast" not in msg, (want, msg)
    m = hybrid_model.copy()
    m.near_plane = "near"
    msg = type_error(lambda: m.save("/tmp/never-written.ply"))
    assert msg.startswith("Model.save: near_plane must be a number, got str"), msg
    msg = type_error(lambda: hgs.render(m, scene, 0))
    assert msg.startswith("render: near_plane must be a number, got str"), msg


def test_every_call_names_a_wrong_argument(hybrid_model, scene, tmp_path, monkeypatch):
    # Each argument of each call replaced by wrong types in turn: every TypeError is one line naming the call or
    # the argument, never pybind11's "incompatible function arguments" list nor "Unable to cast".
    t = hgs.Trainer(scene, "rgb", 2, {"densify": False})
    q = hgs.query(hybrid_model, scene, next(iter(scene.text_embeddings)))
    s = q.session
    z = np.zeros
    calls = {
        "Scene.load": (hgs.Scene.load, [str(tmp_path / "none"), 1]),
        "Scene.features": (scene.features, [0, True]),
        "Model.load": (hgs.Model.load, [str(tmp_path / "none.ply")]),
        "Model.save": (hybrid_model.save, [str(tmp_path / "m.ply")]),
        "Model.select": (hybrid_model.select, [[1], False]),
        "Model": (hgs.Model, [z((2, 3), np.float32), z((2, 3), np.float32), z((2, 4), np.float32),
                              z(2, np.float32), z((2, 1, 3), np.float32), {}]),
        "render": (hgs.render, [hybrid_model, scene, 0]),
        "Trainer": (hgs.Trainer, [scene, "rgb", 2, {}, False]),
        "Trainer.run": (t.run, [2, "", 0, 0, ""]),
        "Trainer.save_checkpoint": (t.save_checkpoint, [str(tmp_path / "c.ckpt")]),
        "QuerySession": (hgs.QuerySession, [scene, hybrid_model, "", None]),
        "QuerySession.ask": (s.ask, ["x", 0.0, 0.1]),
        "QuerySession.object_opacity": (s.object_opacity, [0, [1]]),
        "QuerySession.pixel_relevancy": (s.pixel_relevancy, [0, "x", "objects"]),
        "QuerySession.object_name": (s.object_name, [1]),
        "QuerySession.evaluate": (s.evaluate, ["instances", "object", "objects"]),
        "synth": (hgs.synth, [str(tmp_path / "s")]),
        "set_threads": (hgs.set_threads, [1]),
        "query": (hgs.query, [hybrid_model, scene, "x"]),
        "train": (hgs.train, [scene]),
    }
    monkeypatch.chdir(tmp_path)  # a str where a path goes is a path: keep what it writes in here
    paths = {("Model.save", 0), ("Trainer.save_checkpoint", 0), ("synth", 0)}
    checked = 0
    for name, (fn, good) in calls.items():
        for i in range(len(good)):
            for wrong in (None, 1.5, "x", [1], object(), np.zeros(3)):
                if (name, i) in paths and isinstance(wrong, str):
                    continue
                args = list(good)
                args[i] = wrong
                try:
                    fn(*args)
                except TypeError as e:
                    msg = str(e)
                    checked += 1
                    assert "\n" not in msg and "incompatible" not in msg and "Unable to cast" not in msg, (name, i, msg)
                    assert "must be" in msg or "expected" in msg, (name, i, msg)
                    assert type(wrong).__name__ in msg or "dtype" in msg, (name, i, msg)
                except (hgs.Error, ValueError, RuntimeError):
                    pass  # a value the call accepts as a type and refuses as a value (an unknown view name, ...)
    assert checked > 150
