"""hgs.clip.Model and hgs.sam.Model on the tiny reference weights of tests/data (outputs of the PyTorch
reference implementations, tools/clip_reference and tools/sam_reference), and their errors."""

import json
import os

import numpy as np
import pytest

import hgs

from conftest import TEST_DATA

CLIP = os.path.join(TEST_DATA, "clip", "hf_f32")
SAM = os.path.join(TEST_DATA, "sam")


def rel_err(got, ref):  # as tests/test_util.h max_rel_err: relative to 1 + |ref|
    return float(np.max(np.abs(np.asarray(got, np.float64) - ref) / (1 + np.abs(ref))))


def test_clip_text_image_and_dense():
    m = hgs.clip.Model(os.path.join(CLIP, "model.safetensors"))
    assert m.embed_dim == 32
    with open(os.path.join(TEST_DATA, "clip", "phrases.json")) as f:
        phrases = json.load(f)
    e = m.embed_text(phrases)
    assert e.dtype == np.float32 and e.shape == (len(phrases), 32)
    assert rel_err(e, np.load(os.path.join(CLIP, "text_emb.npy"))) < 5e-6
    raw = np.load(os.path.join(CLIP, "raw.npy")).astype(np.float32)  # [37, 53, 3] in [0, 1]
    assert rel_err(m.embed_image(raw), np.load(os.path.join(CLIP, "raw_emb.npy"))) < 2e-6
    d = m.dense_features(raw, input_size=32)
    assert d.shape == (2, 3, 32)
    assert rel_err(d.reshape(-1), np.load(os.path.join(CLIP, "raw_dense.npy")).reshape(-1)) < 2e-6


def test_sam_prompted_masks():
    m = hgs.sam.Model(os.path.join(SAM, "tiny_sam.safetensors"))
    img = np.load(os.path.join(SAM, "image.npy"))  # uint8 [45, 70, 3]
    emb = m.embed(img)
    ref = np.load(os.path.join(SAM, "embedding.npy"))
    assert rel_err(emb.reshape(-1), ref.reshape(-1)) < 1e-5
    with open(os.path.join(SAM, "prompts.json")) as f:
        p = json.load(f)["prompts"][3]
    masks, iou = m.predict(img, points=p.get("points", []), labels=p.get("labels", []), boxes=p.get("boxes", []))
    assert masks.dtype == bool and masks.shape == (4, 45, 70) and iou.shape == (4,)
    assert rel_err(iou, np.load(os.path.join(SAM, "iou3.npy")).reshape(-1)) < 1e-5
    logits = np.load(os.path.join(SAM, "masks3.npy"))
    sure = np.abs(logits) > 1e-3  # pixels whose sign a float32 rounding cannot flip
    np.testing.assert_array_equal(masks[sure], (logits > 0)[sure])


def test_weights_errors(tmp_path):
    missing = str(tmp_path / "missing.safetensors")
    with pytest.raises(hgs.Error, match="missing.safetensors"):
        hgs.clip.Model(missing)
    with pytest.raises(hgs.Error, match="missing.safetensors"):
        hgs.sam.Model(missing)
    m = hgs.clip.Model(os.path.join(CLIP, "model.safetensors"))
    with pytest.raises(TypeError, match="uint8 or float32"):
        m.embed_image(np.zeros((8, 8, 3), np.int64))
    with pytest.raises(ValueError, match=r"\[H, W, 3\]"):
        m.embed_image(np.zeros((8, 8), np.uint8))
