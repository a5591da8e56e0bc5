"""Shared objects used from several Python threads (issue 60): a query result / session hammered from a thread pool
gives the same masks as serially (it corrupted the heap: one renderer, the GIL released); two threads stepping
one Trainer get one step each or a clear error (it crashed); thread counts are bounded and validated. The crash
cases run in a child interpreter so that a crash is a failed test, not a dead test run."""

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

import hgs

PY = os.path.dirname(os.path.dirname(os.path.abspath(hgs.__file__)))


def run_child(code, *args):
    env = dict(os.environ, PYTHONPATH=PY + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, env=env,
                          timeout=120)


QUERY_HAMMER = r"""
import sys
from concurrent.futures import ThreadPoolExecutor
import numpy as np
import hgs
scene, model = hgs.Scene.load(sys.argv[1]), hgs.Model.load(sys.argv[2])
text = sys.argv[3]
q = hgs.query(model, scene, text)
n = len(scene)
ref = [q.session.object_opacity(i, q.chosen) for i in range(n)]
rel = [q.relevancy(i) for i in range(n)]
for rnd in range(6):
    r = hgs.query(model, scene, text, session=q.session)  # a fresh result: nothing cached
    with ThreadPoolExecutor(4) as ex:
        masks = list(ex.map(r.mask, list(range(n)) * 2))
        rels = list(ex.map(r.relevancy, range(n)))
        asks = list(ex.map(lambda t: r.session.ask(t), [text] * 8))
    for i, m in enumerate(masks):
        assert np.array_equal(m, ref[i % n] > 0.5), f"view {i % n}: mask differs from the serial one"
    for i, x in enumerate(rels):
        assert np.array_equal(x, rel[i]), f"view {i}: relevancy differs"
    assert all(a == asks[0] for a in asks)
print("ok")
"""


def test_query_result_and_session_from_many_threads(hybrid_model, scene, scene_dir, tmp_path):
    model_dir = tmp_path / "model"
    hybrid_model.save(str(model_dir))
    text = next(n for n in scene.object_names.values() if n in scene.text_embeddings)
    r = run_child(QUERY_HAMMER, scene_dir, model_dir, text)
    assert r.returncode == 0 and r.stdout.strip() == "ok", f"exit {r.returncode}: {r.stderr[-2000:]}"


TRAINER_HAMMER = r"""
import sys, threading
import hgs
scene = hgs.Scene.load(sys.argv[1])
t = hgs.Trainer(scene, "hybrid", 400, {"densify": False})
ok, refused, other = [0], [0], []
start = threading.Barrier(2)
def worker():
    start.wait()
    for _ in range(60):
        try:
            t.step()
            ok[0] += 1
        except hgs.Error as e:
            if "already running" in str(e):
                refused[0] += 1
            else:
                other.append(str(e))
threads = [threading.Thread(target=worker) for _ in range(2)]
for th in threads: th.start()
for th in threads: th.join()
assert not other, other
assert t.iteration == ok[0] * t.step_views, (t.iteration, ok[0])
print("ok", ok[0], refused[0])
"""


def test_trainer_stepped_from_two_threads(scene_dir):
    r = run_child(TRAINER_HAMMER, scene_dir)
    assert r.returncode == 0 and r.stdout.startswith("ok"), f"exit {r.returncode}: {r.stderr[-2000:]}"
    ok, refused = map(int, r.stdout.split()[1:])
    assert ok + refused == 120 and ok > 0


def test_second_caller_is_refused_while_the_trainer_runs(scene):
    # Deterministic: run()'s callback holds the trainer between two steps; another thread calling step() or
    # finish() then must be refused (not wait, not crash), while reading the model from the callback works.
    t = hgs.Trainer(scene, "rgb", 4, {"densify": False})
    errors, seen = [], []

    def other():
        for call in (t.step, t.finish, lambda: t.run(4), lambda: t.model):
            try:
                call()
                errors.append("no error")
            except hgs.Error as e:
                errors.append(str(e))

    def on_step(s, it, loss):
        if it == 2:
            th = threading.Thread(target=other)
            th.start()
            th.join()
            seen.append(t.model.n)  # the same thread: between two steps, allowed
        return True

    t.run(4, on_step=on_step)
    assert len(errors) == 4
    assert errors[0].startswith("Trainer.step: already running in another thread"), errors[0]
    assert errors[1].startswith("Trainer.finish: already running"), errors[1]
    assert errors[2].startswith("Trainer.run: already running"), errors[2]
    assert errors[3].startswith("Trainer.model: Trainer.run is running in another thread"), errors[3]
    assert seen == [len(scene.points)] and t.iteration == 4


def test_trainer_step_refused_inside_its_own_run(scene):
    t = hgs.Trainer(scene, "rgb", 4, {"densify": False})
    errors = []

    def on_step(s, it, loss):
        try:
            t.step()
        except hgs.Error as e:
            errors.append(str(e))
        return True

    t.run(4, on_step=on_step)
    assert len(errors) == 4 and "inside Trainer.run" in errors[0] and t.iteration == 4


def test_trainer_step_stops_at_iters(scene):
    t = hgs.Trainer(scene, "rgb", 3, {"densify": False})
    for _ in range(3):
        t.step()
    with pytest.raises(hgs.Error, match=r"Trainer.step: the run's 3 images are done \(iters=3\)"):
        t.step()
    assert t.iteration == 3
    assert t.finish().n == len(scene.points)


@pytest.mark.parametrize("n", [0, -1, 100000, 2**40, "4", 2.5, None, True])
def test_set_threads_bounds(n, hybrid_model, scene):
    with pytest.raises((TypeError, hgs.Error)) as e:
        hgs.set_threads(n)
    if isinstance(n, int) and not isinstance(n, bool):
        assert e.type is hgs.Error
        assert str(e.value).startswith(f"set_threads: n must be 1..{hgs.max_threads()}"), str(e.value)
    else:
        assert e.type is TypeError and str(e.value).startswith("set_threads: n must be an int, got "), str(e.value)
    hgs.render(hybrid_model, scene, 0)  # still renders with the previous count
    if n is not None:  # hgs.train's threads=None keeps the count
        with pytest.raises((hgs.Error, TypeError), match="^hgs.train: threads must be"):
            hgs.train(scene, iters=1, threads=n, progress=False)


def test_set_threads_accepts_the_bound():
    top = hgs.max_threads()
    assert top == 4 * os.cpu_count()  # the documented bound: 4x the hardware threads
    hgs.set_threads(top)
    hgs.set_threads(1)
    hgs.set_threads(os.cpu_count() or 1)


THREADS_RENDER = r"""
import sys
import hgs
scene, model = hgs.Scene.load(sys.argv[1]), hgs.Model.load(sys.argv[2])
try:
    hgs.set_threads(100000)
except hgs.Error as e:
    print("refused:", e)
hgs.render(model, scene, 0)
print("rendered")
"""


def test_huge_thread_count_then_render_does_not_crash(hybrid_model, scene_dir, tmp_path):
    model_dir = tmp_path / "model"
    hybrid_model.save(str(model_dir))
    r = run_child(THREADS_RENDER, scene_dir, model_dir)
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr[-2000:]}"
    assert "refused: set_threads: n must be 1.." in r.stdout and "rendered" in r.stdout


def test_threads_option_of_the_command_line(hgs_binary, tmp_path):
    # Every command's --threads, parsed the same way (cli::add_threads_option): 100000 crashed prepare and synth.
    top = hgs.max_threads()
    s, m, o = str(tmp_path / "scene"), str(tmp_path / "model"), str(tmp_path / "out")
    commands = {"synth": ["--out", o], "prepare": [s, "--out", o, "--until", "input"], "train": [s, "--out", o],
                "render": [s, m, "--out", o], "query": [s, m, "--text", "x", "--out", o], "eval": [s, m, "--out", o],
                "view": [s, m], "ablate": [s, "--out", o], "features": [s], "embed-text": ["--text", "x"],
                "masks generate": [s], "masks click": [s]}
    for cmd, args in commands.items():
        for n in ("0", "-3", str(top + 1), "100000", "x"):
            r = subprocess.run([hgs_binary, *cmd.split(), *args, "--threads", n, "--quiet"], capture_output=True,
                               text=True)
            assert r.returncode == 2, (cmd, n, r.returncode, r.stderr)
            lines = r.stderr.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("hgs: error: --threads:"), (cmd, n, r.stderr)
            assert f"(see `hgs {cmd} --help`)" in lines[0], lines[0]
            if n != "x":
                assert f"must be 1..{top} " in lines[0] and lines[0].count(f"got {n} ") == 1, lines[0]
            assert not os.path.exists(o)


def test_huge_omp_num_threads_is_refused(hgs_binary, tmp_path):
    # OMP_NUM_THREADS=100000 crashed at the first parallel region, like --threads 100000.
    env = dict(os.environ, OMP_NUM_THREADS="100000", PYTHONPATH=PY + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([hgs_binary, "synth", "--out", str(tmp_path / "s"), "--quiet"], capture_output=True, text=True,
                       env=env)
    assert r.returncode == 2 and r.stderr.startswith("hgs: error: OMP_NUM_THREADS: must be 1.."), r.stderr
    assert r.stderr.count("\n") == 1 and not (tmp_path / "s").exists()
    r = subprocess.run([sys.executable, "-c", "import hgs"], capture_output=True, text=True, env=env)
    assert r.returncode == 1 and "OMP_NUM_THREADS: must be 1.." in r.stderr.strip().splitlines()[-1], r.stderr


def test_model_and_scene_shared_by_threads(hybrid_model, scene, tmp_path):
    # Read-only to every call: render, image, select and save of one model / scene from 4 threads at once give
    # what they give serially.
    from concurrent.futures import ThreadPoolExecutor
    n = len(scene)
    ref = [hgs.render(hybrid_model, scene, i)["rgb"] for i in range(n)]
    images = [scene.image(i) for i in range(n)]
    chosen = [1]
    sel = hybrid_model.select(chosen).n
    with ThreadPoolExecutor(4) as ex:
        rgbs = list(ex.map(lambda i: hgs.render(hybrid_model, scene, i % n)["rgb"], range(3 * n)))
        imgs = list(ex.map(scene.image, range(n)))
        sels = list(ex.map(lambda _: hybrid_model.select(chosen).n, range(8)))
        saved = list(ex.map(lambda k: hybrid_model.save(str(tmp_path / f"m{k}")), range(4)))
    for i, x in enumerate(rgbs):
        np.testing.assert_array_equal(x, ref[i % n])
    for a, b in zip(imgs, images):
        np.testing.assert_array_equal(a, b)
    assert sels == [sel] * 8
    for p in saved:
        np.testing.assert_array_equal(hgs.Model.load(p).means, hybrid_model.means)
