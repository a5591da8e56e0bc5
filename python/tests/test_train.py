"""hgs.train: the callback (its information, stopping training), Ctrl-C, options, the output folder, and the
same model as `hgs train` from the command line."""

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import hgs


def test_callback_reports_and_stops(scene):
    calls = []

    def cb(info):
        calls.append(info)
        return len(calls) < 2  # stop at the second call

    m = hgs.train(scene, iters=1000, callback=cb, callback_every=20, progress=False, densify=False)
    assert [c["iteration"] for c in calls] == [20, 40]
    assert m.train_stats["iterations"] == 40 and m.train_stats["stopped"] == "callback"
    c = calls[-1]
    assert set(c) >= {"iteration", "loss", "terms", "psnr", "num_gaussians", "ms_per_iter", "elapsed_s"}
    assert set(c["terms"]) == {"rgb", "app", "bro", "sem"}
    assert c["loss"] == pytest.approx(sum(c["terms"].values()), rel=1e-6)
    assert c["num_gaussians"] == m.n and c["ms_per_iter"] > 0


def test_ctrl_c_stops_at_the_next_step(scene):
    calls = []
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        m = hgs.train(scene, method="rgb", iters=1000000, progress=False, callback=calls.append, callback_every=1)
    finally:
        timer.cancel()
    assert m.train_stats["stopped"] == "interrupted"
    it = m.train_stats["iterations"]
    assert 0 < it < 1000000 and it - 1 <= len(calls) <= it  # ended within a step of the interrupt
    assert np.isfinite(m.means).all()


def test_options_and_errors(scene):
    with pytest.raises(hgs.Error, match="unknown option 'lambda_nope'"):
        hgs.train(scene, iters=10, progress=False, lambda_nope=1.0)
    with pytest.raises(hgs.Error, match="use_of"):  # a hybrid option for the rgb method
        hgs.train(scene, method="rgb", iters=10, progress=False, use_of=False)
    with pytest.raises(hgs.Error, match="'batch' must be 1..4096"):
        hgs.train(scene, iters=10, progress=False, batch=0)
    with pytest.raises(hgs.Error, match="sh_degree"):
        hgs.train(scene, iters=10, progress=False, sh_degree="three")
    with pytest.raises(hgs.Error, match="method"):
        hgs.train(scene, method="nerf", iters=10, progress=False)
    with pytest.raises(hgs.Error) as e:
        hgs.train("/no/such/scene", iters=10, progress=False)
    assert "/no/such/scene" in str(e.value)
    with pytest.raises(ValueError):
        hgs.train(scene, iters=10, progress=False, callback_every=0)
    m = hgs.train(scene, method="rgb", iters=8, progress=False, sh_degree=1, densify=False, seed=3)
    assert m.sh_degree == 1 and m.n == len(scene.points)


def test_same_model_as_the_command_line(scene, scene_dir, hgs_binary, tmp_path):
    # The binding drives the library's Trainer step by step; `hgs train` loops in C++. Same scene, same options:
    # the same PLY bit for bit.
    iters = 30
    cli = tmp_path / "cli"
    subprocess.run([hgs_binary, "train", scene_dir, "--out", str(cli), "--iters", str(iters), "--quiet"],
                   check=True, capture_output=True)
    py = tmp_path / "py"
    m = hgs.train(scene, out=str(py), iters=iters, progress=False)
    assert (py / "point_cloud.ply").read_bytes() == (cli / "point_cloud.ply").read_bytes()
    ref = hgs.Model.load(str(cli))
    np.testing.assert_array_equal(m.means, ref.means)
    with open(py / "config.json") as f:
        cfg_py = json.load(f)
    with open(cli / "config.json") as f:
        cfg_cli = json.load(f)
    assert cfg_py == cfg_cli
    with open(py / "train_stats.json") as f:
        stats_py = json.load(f)
    with open(cli / "train_stats.json") as f:
        stats_cli = json.load(f)
    assert stats_py["iterations"] == iters and stats_py["stopped"] is None
    assert set(stats_py) == set(stats_cli)  # one schema (docs/formats.md), whoever trains
    assert set(m.train_stats) == set(stats_py) and m.train_stats["wall_time_s"] == stats_py["wall_time_s"]


def test_progress_bar_in_a_log(scene, capfd):
    hgs.train(scene, method="rgb", iters=20, progress=True)
    err = capfd.readouterr().err
    assert "train [" in err and "20/20" in err and "ETA" in err and "\r" not in err  # not a terminal: plain lines


def test_checkpoints_and_resume(scene, tmp_path):
    # save_every writes checkpoints as `hgs train --save-every`; resuming from one gives the uninterrupted model.
    full = hgs.train(scene, out=str(tmp_path / "full"), iters=40, save_every=20, progress=False)
    assert (tmp_path / "full" / "checkpoints" / "iter_20.ckpt").exists()
    assert (tmp_path / "full" / "checkpoints" / "iter_40.ckpt").exists()
    assert (tmp_path / "full" / "point_cloud_iter_20.ply").exists()
    resumed = hgs.train(scene, iters=40, progress=False, resume=tmp_path / "full" / "checkpoints" / "iter_20.ckpt")
    assert resumed.train_stats["iterations_this_run"] == 20
    np.testing.assert_array_equal(resumed.means, full.means)
    np.testing.assert_array_equal(resumed.language, full.language)
    with pytest.raises(ValueError, match="save_every"):
        hgs.train(scene, iters=40, save_every=20, progress=False)
    with pytest.raises(hgs.Error, match="nothing to do"):
        hgs.train(scene, iters=20, progress=False, resume=tmp_path / "full" / "checkpoints" / "iter_20.ckpt")


def test_trainer_step_by_step(scene):
    t = hgs.Trainer(scene, "rgb", 6, {"densify": False, "near_plane": 0.05})
    infos = [t.step() for _ in range(3)]
    assert t.iteration == 3 and t.step_views == 1 and t.iters == 6
    assert all(i.num_gaussians == len(scene.points) and i.ms > 0 for i in infos)
    assert set(infos[0].terms) == {"rgb"} and infos[0].loss == pytest.approx(infos[0].terms["rgb"])
    assert set(infos[0].times) >= {"forward", "backward", "update"}
    snapshot = t.model  # a copy: later steps do not change it
    assert snapshot.near_plane == pytest.approx(0.05)  # seen as the run sees it
    before = snapshot.means.copy()
    t.step()
    np.testing.assert_array_equal(snapshot.means, before)
    m = t.finish()
    assert not np.array_equal(m.means, before)
    assert m.near_plane == pytest.approx(0.05)
    with pytest.raises(hgs.Error, match="finished"):
        t.step()


def test_training_steps_release_the_gil(scene):
    # With a switch interval of 5 s a thread that held the GIL through its steps would keep it for the whole run
    # (it never blocks): the main thread, sleeping 0.2 ms at a time, could not wake until it ended. Steps that
    # release the GIL let the main thread run all along.
    t = hgs.Trainer(scene, "rgb", 60, {"densify": False})
    done = threading.Event()

    def run():
        for _ in range(60):
            t.step()
        done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(5.0)
    try:
        worker = threading.Thread(target=run)
        worker.start()
        ticks = 0
        while not done.is_set():
            ticks += 1
            time.sleep(0.0002)
        worker.join()
    finally:
        sys.setswitchinterval(old)
    assert t.iteration == 60 and ticks >= 20


def test_progress_bar_redraws_in_a_terminal_and_in_jupyter(monkeypatch):
    import io
    import types

    class Tty(io.StringIO):
        def isatty(self):
            return True

    def run(stream):
        bar = hgs._Progress("train", 10, stream=stream)
        for i in range(1, 11):
            bar.update(i, "loss 0.1")
        bar.finish(10, "N 5")
        return stream.getvalue()

    out = run(Tty())
    assert out.startswith("\r") and "10/10" in out and out.endswith("\n") and out.count("\n") == 1
    assert out.rstrip().endswith("N 5")  # the last redraw, padded over the longer line before it
    assert "\r" not in run(io.StringIO())  # a log: plain lines
    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))  # as inside Jupyter
    out = run(io.StringIO())
    assert out.startswith("\r") and out.count("\n") == 1
