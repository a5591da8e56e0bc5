"""hgs: Hybrid Gaussians for open-vocabulary 3D segmentation, from Python (docs/python.md).

The C++ library does the work (module ``hgs._hgs``); this package adds the training loop with its callback,
progress bar and Ctrl-C handling, and the query / evaluate helpers. Arrays are numpy; the model's arrays are
views on its own storage.

    import hgs
    scene = hgs.Scene.load("scene")
    model = hgs.train(scene, iters=3000)
    answer = hgs.query(model, scene, "red mug")
    mask = answer.mask(0)                   # bool [H, W]
"""

import json
import math
import os
import sys
import time

from . import _openblas_env


def _set_openblas_env():
    # OpenBLAS reads these once, when the library is loaded (by _hgs below, or by numpy before it): the same
    # choice as the hgs executables make (src/nn/openblas_env.h). Values the user set are kept, and
    # HGS_OPENBLAS_ENV=0 leaves everything to OpenBLAS.
    if os.environ.get("HGS_OPENBLAS_ENV") == "0":
        return
    core = _openblas_env.core_for_this_cpu()
    if core and "OPENBLAS_CORETYPE" not in os.environ:
        os.environ["OPENBLAS_CORETYPE"] = core
    os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", _openblas_env.thread_timeout)


_set_openblas_env()

try:  # after the OpenBLAS settings above: numpy loads the same OpenBLAS
    import numpy as _numpy  # noqa: F401  (every array hgs hands out is numpy's)
except ImportError as e:
    raise ImportError(
        f"hgs needs numpy in this interpreter ({sys.executable}): Debian's python3-numpy (scripts/setup) is for "
        "/usr/bin/python3, the interpreter hgs is built for (docs/python.md)") from e

from . import _argcheck, _hgs  # noqa: E402  (after the environment above)

# Wrong argument types: one line naming the call and the argument, not pybind11's list of signatures (_argcheck.py).
_argcheck.install(_hgs, [_hgs.Model, _hgs.Scene, _hgs.Trainer, _hgs.QuerySession],
                  ["render", "synth", "set_threads", "method_names", "max_threads"])
_argcheck.install(_hgs.clip, [_hgs.clip.Model], [], prefix="clip.")
_argcheck.install(_hgs.sam, [_hgs.sam.Model], [], prefix="sam.")

from ._hgs import (  # noqa: E402  (after the environment above)
    Error,
    Model,
    QuerySession,
    Scene,
    StepInfo,
    Trainer,
    View,
    __version__,
    clip,
    max_threads,
    method_names,
    render,
    sam,
    set_threads,
    synth,
)

# hgs.clip and hgs.sam are submodules of _hgs: make `import hgs.clip` find them too.
sys.modules[__name__ + ".clip"] = clip
sys.modules[__name__ + ".sam"] = sam

# The near plane hgs.render and QuerySession cull a model at: Model.load, hgs.train and Trainer.model / finish set
# it on the instance (the model's config), copy and select carry it over; a model made from arrays has the
# renderer's default.
Model.near_plane = 0.01

__all__ = [
    "Error", "Model", "QueryResult", "QuerySession", "Scene", "StepInfo", "Trainer", "View", "clip", "evaluate",
    "max_threads", "method_names", "query", "render", "sam", "set_threads", "synth", "train",
]


# ---- progress bar -------------------------------------------------------------------------------------------

class _Progress:
    """A progress bar with rate and ETA on sys.stderr: redrawn in place (carriage return) in a terminal and in
    Jupyter, whose output areas honour it; elsewhere (logs, CI) a plain line every 10 % or 30 s."""

    def __init__(self, label, total, stream=None):
        self.label, self.total = label, max(1, total)
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", lambda: False)
        self.live = bool(isatty()) or "ipykernel" in sys.modules
        self.t0 = time.perf_counter()
        self.last_print, self.last_done, self.width = 0.0, -1, 0

    def _line(self, done, status):
        el = time.perf_counter() - self.t0
        frac = min(1.0, done / self.total)
        eta = el / done * (self.total - done) if done > 0 else float("nan")
        rate = done / el if el > 0 else 0.0
        bar = "#" * int(frac * 20)
        eta_s = "?" if math.isnan(eta) else _duration(eta)
        return (f"{self.label} [{bar:<20}] {done}/{self.total} {100 * frac:5.1f}% {rate:.1f}/s "
                f"ETA {eta_s}" + (f"  {status}" if status else ""))

    def update(self, done, status=""):
        now = time.perf_counter()
        if self.live:
            if now - self.last_print < 0.1 and done < self.total:
                return
            line = self._line(done, status)
            self.stream.write("\r" + line + " " * max(0, self.width - len(line)))
            self.width = len(line)
        else:
            step = max(1, self.total // 10)
            if done // step == self.last_done // step and now - self.last_print < 30 and done < self.total:
                return
            self.stream.write(self._line(done, status) + "\n")
        self.stream.flush()
        self.last_print, self.last_done = now, done

    def finish(self, done, status=""):
        if self.live:  # the bar as it ends, then a new line
            self.last_print = 0.0
            self.update(done, status)
            self.stream.write("\n")
        else:  # one closing line
            el = time.perf_counter() - self.t0
            line = f"{self.label}: {done}/{self.total} in {_duration(el)}"
            self.stream.write(line + (f"  {status}" if status else "") + "\n")
        self.stream.flush()


def _duration(s):
    if s >= 3600:
        return f"{int(s // 3600)}h{int(s % 3600 // 60):02d}m"
    if s >= 60:
        return f"{int(s // 60)}m{int(s % 60):02d}s"
    return f"{s:.1f}s"


# ---- training -----------------------------------------------------------------------------------------------

def _as_scene(scene, downscale=1, where="train"):
    if isinstance(scene, Scene):
        return scene
    if not isinstance(scene, (str, os.PathLike)):
        raise TypeError(f"{where}: scene must be an hgs.Scene or a scene folder (str or os.PathLike), "
                        f"got {type(scene).__name__}")
    return Scene.load(os.fspath(scene), downscale)


def _as_model(model, where):
    if isinstance(model, Model):
        return model
    if not isinstance(model, (str, os.PathLike)):
        raise TypeError(f"{where}: model must be an hgs.Model or a model PLY / folder (str or os.PathLike), "
                        f"got {type(model).__name__}")
    return Model.load(os.fspath(model))


def train(scene, out=None, method="hybrid", iters=30000, callback=None, callback_every=100, progress=True,
          threads=None, resume=None, test_every=0, **options):
    """Trains Hybrid Gaussians (method="hybrid", the default) or plain 3DGS (method="rgb") on a scene and returns
    the trained hgs.Model.

    scene: an hgs.Scene or a scene folder. out: a model folder to write (point_cloud.ply, config.json,
    train_stats.json), or None. iters: training images to see; the 30k schedule (densification) is scaled to it,
    as `hgs train --iters` does. callback(info) is called every `callback_every` images and at the end, with a
    dict: iteration, loss, terms (weighted loss terms), psnr, num_gaussians, ms_per_iter (mean since the last
    call), elapsed_s; when it returns False training stops and the model so far is returned. Ctrl-C
    (KeyboardInterrupt) stops training the same way at the end of the running step; the model folder's final
    files are written as one change, so a second Ctrl-C while they are written lets them finish and then raises.
    progress: a progress bar on stderr (terminal or Jupyter). threads: worker threads, 1..hgs.max_threads()
    (hgs.set_threads). options: the training configuration
    by name (seed, sh_degree, densify, white_bg, batch, batch_lr, learning rates, ...) and, for the hybrid method,
    its options (use_of, use_scl, use_bro, lambda_app, lambda_sem, lambda_bro, objects_per_step, ...); see
    docs/python.md. An unknown name raises hgs.Error. With save_every=N (a multiple of the views per step) and
    `out`, a checkpoint out/checkpoints/iter_<i>.ckpt and a PLY are written every N images (and a checkpoint at
    the end), as `hgs train --save-every` does; resume=CHECKPOINT continues such a run bit for bit. test_every=N
    scores the held-out views every N images (train_stats["test_curve"], as `hgs train --test-every`). The loop,
    checkpoints, statistics and the output folder are the library's training run, the one `hgs train` uses
    (train/run.h); model.train_stats is its train_stats.json.
    """
    if "downscale" in options:
        if isinstance(scene, Scene):
            raise ValueError("downscale: the scene is loaded already (hgs.Scene.load(path, downscale))")
        scene = _as_scene(scene, int(options.pop("downscale")))
    scene = _as_scene(scene)
    if threads is not None:
        try:
            set_threads(threads)
        except (Error, TypeError) as e:  # name hgs.train's argument
            raise type(e)(str(e).replace("set_threads: n", "hgs.train: threads", 1)) from None
    if int(callback_every) < 1:
        raise ValueError(f"callback_every must be >= 1, got {callback_every}")
    if callback is not None and not callable(callback):
        raise TypeError("callback must be callable (or None)")
    save_every = int(options.get("save_every", 0))
    if save_every and out is None:
        raise ValueError("save_every: checkpoints need an output folder (out=...)")
    if out is not None:
        out = os.fspath(out)
    trainer = Trainer(scene, method, int(iters), dict(options), False)
    G = trainer.step_views
    if save_every % G:
        raise ValueError(f"save_every {save_every} is not a multiple of the {G} views of a step")
    resumed_from = ""
    if resume is not None:
        resumed_from = os.fspath(resume)
        trainer.load_checkpoint(resumed_from)
    start = trainer.iteration
    bar = _Progress("train", iters - start) if progress else None
    window = {"ms": 0.0, "steps": 0}
    t0 = time.perf_counter()

    def on_step(s, it, loss_average):
        # After every step of the library's run (train/run.h): the progress bar and the user's callback.
        window["ms"] += s.ms
        window["steps"] += 1
        if bar is not None:
            bar.update(it - start, f"loss {loss_average:.4f} psnr {s.psnr:.2f} N {s.num_gaussians} {s.ms:.1f} ms/it")
        if callback is not None and (it // callback_every > (it - G) // callback_every or it >= iters):
            info = {"iteration": it, "loss": s.loss, "terms": s.terms, "psnr": s.psnr,
                    "num_gaussians": s.num_gaussians, "ms_per_iter": window["ms"] / window["steps"] / G,
                    "elapsed_s": time.perf_counter() - t0}
            window["ms"], window["steps"] = 0.0, 0
            if callback(info) is False:
                return False
        return True

    stats = json.loads(trainer.run(int(iters), out or "", save_every, int(test_every),
                                   resumed_from, on_step))
    model = trainer.finish()  # with the run's near_plane: hgs.render and QuerySession cull as training did
    stopped = stats["stopped"]
    if bar is not None:
        note = {"callback": " (stopped by the callback)", "interrupted": " (interrupted)"}.get(stopped, "")
        bar.finish(stats["iterations"] - start, f"N {model.n}{note}")
    model.train_stats = stats
    if stopped == "interrupted":
        print(f"hgs.train: interrupted at iteration {stats['iterations']}; returning the model so far", file=sys.stderr)
    return model


# ---- queries and evaluation ---------------------------------------------------------------------------------

class QueryResult:
    """The answer to a text query: every object ranked (best first), the chosen ones, and on demand their
    rendered opacity and masks per view, the pixel relevancy map, and the chosen objects' Gaussians."""

    def __init__(self, session, model, scene, text, objects, views, mask_threshold):
        self.session, self.model, self.scene, self.text = session, model, scene, text
        self.objects = objects  # [{id, name, relevancy, cosine, chosen, anchor}], best first
        # The anchor first (query.h: choose_objects), then the other chosen objects best first.
        self.chosen = [o["id"] for o in objects if o["anchor"]] + [o["id"] for o in objects
                                                                  if o["chosen"] and not o["anchor"]]
        self.views = views  # view indices of `masks`
        self.mask_threshold = mask_threshold
        self._opacity = {}

    @property
    def best(self):
        """The answer's anchor, the first chosen object: {id, name, relevancy, cosine, chosen, anchor}. It is the
        best ranked object unless that one holds no Gaussians of its own (query.h: choose_objects)."""
        return next(o for o in self.objects if o["anchor"])

    def opacity(self, view):
        """Rendered opacity of the chosen objects in a view (index or name), summed: float32 [H, W]."""
        i = self.scene.index(view)
        if i not in self._opacity:
            self._opacity[i] = self.session.object_opacity(i, self.chosen)
        return self._opacity[i]

    def mask(self, view, threshold=None):
        """Mask of the chosen objects in a view: opacity > threshold (default mask_threshold), bool [H, W]."""
        return self.opacity(view) > (self.mask_threshold if threshold is None else threshold)

    @property
    def masks(self):
        """{view name: bool [H, W]} over the views asked for (hgs.query's `views`)."""
        return {self.scene.view(i).name: self.mask(i) for i in self.views}

    def relevancy(self, view, relevancy="objects"):
        """A pixel score map for the text, float32 [H, W]. relevancy: "objects" (the default: the cosine with
        hgs's object-embedding map sum_k A_k e_k, each object's pooled embedding rendered with its opacity; a rule
        of this project, not in the paper; a pixel where nothing is rendered scores as the view's lowest rendered
        pixel), "objects-lerf" (LERF's relevancy of that map), "lerf" (the paper's
        language map, eq. 8 summed over objects = sum_n f_n alpha T, scored with LERF's relevancy as LangSplat
        scores its field) or "foreground" (lerf times the rendered foreground opacity)."""
        return self.session.pixel_relevancy(self.scene.index(view), self.text, relevancy)

    def select(self, remove=False):
        """The chosen objects' Gaussians as a new hgs.Model (or the scene without them, remove=True)."""
        return self.model.select(self.chosen, remove)

    def export(self, path, remove=False):
        """Writes select(remove) as a 3DGS PLY (with the hybrid channels); returns the file written."""
        return self.select(remove).save(os.fspath(path))

    def __repr__(self):
        b = self.best
        return f"<hgs.QueryResult '{self.text}': object {b['id']} ({b['name']}), relevancy {b['relevancy']:.3f}>"


def _view_list(scene, views):
    if views is None or views == "all":
        return list(range(len(scene)))
    if views == "test":
        return list(scene.test_indices)
    if views == "train":
        return list(scene.train_indices)
    if isinstance(views, (int, str)):
        views = [views]
    return [scene.index(v) for v in views]


def query(model, scene, text, views=None, min_relevancy=0.0, mask_threshold=0.5, clip=None, session=None,
          fragment_margin=None, anchor_support=0.0):
    """Answers a text query on a trained hybrid model: returns a QueryResult (objects ranked by their embedding's
    cosine with the text, with their LERF relevancy; the best one that holds Gaussians of its own chosen (the
    anchor), plus every other with relevancy >= min_relevancy when that is > 0, plus the fragments of the anchor:
    labels whose cosine is below its cosine by at most fragment_margin times its lead over the median label and
    whose Gaussians lie where its Gaussians lie, as SAM2 leaves one object under several ids; a rule of hgs,
    query/fragments.h; None = the library's default, 0 = the anchor alone). anchor_support > 0: the anchor must
    render at least that fraction of the pixels its mask id covers in the training views' masks (a rule of hgs,
    off by default; 0.25 was chosen on the development seeds, docs/ablation.md; needs the scene's masks). views:
    the views of result.masks ("all" = None, "test", "train", or a list of indices / names); masks are rendered
    when first asked for.
    Texts are embedded from the scene's text_embeddings.json, or by OpenCLIP weights `clip`. A QuerySession
    given as `session` is reused (several queries on one model)."""
    scene, model = _as_scene(scene, where="query"), _as_model(model, "query")
    if not isinstance(text, str):
        raise TypeError(f"query: text must be a str, got {type(text).__name__}")
    if session is None:
        session = QuerySession(scene, model, "" if clip is None else os.fspath(clip))
    kw = {"anchor_support": float(anchor_support)}
    if fragment_margin is not None:
        kw["fragment_margin"] = float(fragment_margin)
    objects = session.ask(text, float(min_relevancy), **kw)
    return QueryResult(session, model, scene, text, objects, _view_list(scene, views), float(mask_threshold))


def evaluate(model, scene, protocol="instances", mode="both", relevancy="objects", mask_threshold=0.5, clip=None,
             overlays=None, progress=False, paper_map=True, queries=None, fragment_margin=None, anchor_support=0.0):
    """Evaluates a trained hybrid model with a benchmark protocol (lerf-ovs, 3d-ovs or instances, or a variant:
    3d-ovs-labelled, lerf-ovs-scaled, instances-scaled; see `hgs eval --help`) in object mode, pixel mode or both,
    as `hgs eval` does; returns the report as a dict {"reports": [...]} (report.json's layout: per mode the
    records, the means, mAcc / mIoU / mBIoU). relevancy: pixel mode's score (QueryResult.relevancy); the default
    "objects" is hgs's object-embedding map (not in the paper), and with paper_map (default) pixel mode also
    reports the paper's language map scored with LERF's relevancy (relevancy "lerf") as a report of mode
    "pixel-paper-map", right after the "pixel" one. overlays: a folder for overlay PNGs. queries: a query set of
    the scene's gt/queries.json asked instead of the names (instances protocols: "synonyms", "hypernyms",
    "attributes"). fragment_margin: object mode's fragment rule (see query; None = the library's default, 0 = the
    anchor alone). anchor_support: object mode's anchor support (see query; 0 = off)."""
    scene, model = _as_scene(scene, where="evaluate"), _as_model(model, "evaluate")
    session = QuerySession(scene, model, "" if clip is None else os.fspath(clip))
    args = [protocol, mode, relevancy, float(mask_threshold), "" if overlays is None else os.fspath(overlays),
            bool(progress), bool(paper_map), "" if queries is None else str(queries)]
    kw = {"anchor_support": float(anchor_support)}
    if fragment_margin is not None:
        kw["fragment_margin"] = float(fragment_margin)
    text = session.evaluate(*args, **kw)
    return json.loads(text)
