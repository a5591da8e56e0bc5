#!/usr/bin/env python3
"""Overhead of the Python binding on training: hgs.train (the loop in Python: one Trainer.step() per step with the
GIL released, the loss average, a callback every 100 steps) against `hgs train` (the same library loop in C++) on
one synthetic scene with the same options, so the same steps bit for bit (python/tests/test_train.py checks the
models are identical). The runs alternate (C++, Python, C++, ...); each reports the training loop's wall time per
step (the scene and the initialisation excluded on both sides: train_stats.json mean_ms_per_iter and
Model.train_stats). Prints the median over the rounds of each side and their ratio, the same for the fastest
run of each side, and the Python loop's own time per step outside the library's step (docs/python.md).

    PYTHONPATH=build/python python3 bench/python_overhead.py --hgs build/hgs [--steps 200] [--rounds 5]
        [--method hybrid|rgb|both] [--threads N]
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

import hgs


def cpp_run(hgs_bin, scene_dir, out, method, steps, threads):
    cmd = [hgs_bin, "train", scene_dir, "--out", out, "--method", method, "--iters", str(steps), "--quiet"]
    if threads:
        cmd += ["--threads", str(threads)]
    subprocess.run(cmd, check=True, capture_output=True)
    with open(os.path.join(out, "train_stats.json")) as f:
        return json.load(f)["mean_ms_per_iter"]


def py_run(scene, method, steps):
    m = hgs.train(scene, method=method, iters=steps, progress=False, callback=lambda info: None, callback_every=100)
    st = m.train_stats
    # The loop's time per step outside the library's step (Python, the GIL, the binding, the callback): what the
    # binding adds, without the run-to-run noise of the step itself.
    return st["mean_ms_per_iter"], st["mean_ms_per_iter"] - st["mean_step_ms"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hgs", default="build/hgs", help="the hgs executable of the same build")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--method", default="both", choices=["hybrid", "rgb", "both"])
    ap.add_argument("--threads", type=int, default=0, help="worker threads on both sides (0 = all CPUs)")
    a = ap.parse_args()
    if a.threads:
        hgs.set_threads(a.threads)
    with tempfile.TemporaryDirectory() as tmp:
        scene_dir = os.path.join(tmp, "scene")
        # The synthetic tabletop at its default size, 24 views, 20k SfM points, D = 512.
        hgs.synth(scene_dir, views=24, points=20000, supersample=1)
        scene = hgs.Scene.load(scene_dir)
        print(f"scene: 24 views 320x240, 20000 points, D = 512; {a.steps} steps per run, {a.rounds} rounds, "
              f"threads {a.threads or 'all'}")
        for method in (["hybrid", "rgb"] if a.method == "both" else [a.method]):
            cpp, py, outside = [], [], []
            for r in range(a.rounds):
                cpp.append(cpp_run(a.hgs, scene_dir, os.path.join(tmp, f"cpp_{method}_{r}"), method, a.steps,
                                   a.threads))
                ms, out_ms = py_run(scene, method, a.steps)
                py.append(ms)
                outside.append(out_ms)
                print(f"  {method} round {r + 1}: C++ {cpp[-1]:.3f} ms/step, Python {py[-1]:.3f} ms/step",
                      file=sys.stderr)
            # Medians, and the fastest run of each side (the one least disturbed by other processes).
            for what, f in (("median", statistics.median), ("fastest", min)):
                c, p = f(cpp), f(py)
                print(f"{method:>6} {what:>7}: C++ {c:8.3f} ms/step  Python {p:8.3f} ms/step  Python / C++ "
                      f"{p / c:.4f} ({100 * (p / c - 1):+.2f} %)")
            o = statistics.median(outside)
            print(f"{method:>6} Python loop outside the step: {1000 * o:.1f} us/step median "
                  f"({100 * o / statistics.median(py):.3f} % of a step)")


if __name__ == "__main__":
    main()
