"""Fixtures of the hgs Python tests: one tiny synthetic scene for the session (written by hgs.synth into a temp
folder), a short hybrid and a short RGB training on it, and the hgs executable of the same build (HGS_BINARY, set
by ctest) for the tests that compare the binding with the command line."""

import os
import shutil

import pytest

import hgs

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TEST_DATA = os.path.join(REPO, "tests", "data")

# The tiny scene: 12 views of 80 x 60 pixels, 3 objects, 16-dimensional features, in the simple world's objects-only
# variant (mask ids 1..3; cf. tests/synth_options.h; test_scene.py checks the default world).
SYNTH = dict(world="simple", views=12, width=80, height=60, objects=3, points=1500, feature_dim=16, supersample=1, noise="low",
             objects_only=True)
HYBRID_ITERS = 120


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory):
    out = str(tmp_path_factory.mktemp("synth") / "scene")
    hgs.synth(out, **SYNTH)
    return out


@pytest.fixture(scope="session")
def scene(scene_dir):
    return hgs.Scene.load(scene_dir)


@pytest.fixture(scope="session")
def hybrid_model(scene):
    return hgs.train(scene, iters=HYBRID_ITERS, progress=False)


@pytest.fixture(scope="session")
def rgb_model(scene):
    return hgs.train(scene, method="rgb", iters=40, progress=False)


@pytest.fixture(scope="session")
def hgs_binary():
    b = os.environ.get("HGS_BINARY") or shutil.which("hgs")
    if not b or not os.path.exists(b):
        pytest.skip("the hgs executable is not known (ctest sets HGS_BINARY)")
    return b
