"""EdgeTrack 2D tracker on onnxruntime (no torch): a depthwise-separable Siamese tracker with a
classification + box-regression head, built for one CPU thread, that knows when it has lost
the target.

Two ONNX graphs (written by `track3d-train edgetrack export`):
    <name>_template.onnx  uint8 (1, 128, 128, 3) RGB template crop -> kernel (1, 64, C), once per init
    <name>_search.onnx    uint8 (1, N, N, 3) RGB search crop + kernel -> logit (1, n, n), ltrb (1, 4, n, n)

Per frame: one search crop around the last centre (`track3d.siamfc.crop_square`: one
bilinear warp of fixed arithmetic, `track3d.resample`, or 2 x 2 box halvings + a bilinear resize when shrinking by more than 2; where it
reaches past the image it is filled with the model's pad colour, metadata 'pad', else the frame's
mean colour), one ORT call, then
numpy: the box of every cell from its (l, t, r, b) distances, a size / aspect change penalty,
a cosine window, the best cell, its logit calibrated into `score` (0..1), and a damped size
update (SiamRPN / NanoTrack post-processing).

Lost and found: when `score` falls below the threshold, `update` returns ok=False and the box
stays where it was; while lost the search crop is wider (`lost_instance_size` pixels at the
same image scale, so the template still matches) and has no cosine window, and after
SWEEP_AFTER lost frames every other search steps over a grid of the whole image; the first
frame whose score reaches `reacquire_threshold` (metadata; at least the lost threshold)
re-acquires the target there, and the frame after
a re-acquisition searches the wide region too (the body's motion is not known yet).

Every size and hyper-parameter comes from the models' metadata (key 'track3d'); keyword
overrides to `create` / `EdgeTracker` win over it.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import cv2
import numpy as np

from .frames import MAX_BOX_SCALE, MIN_BOX_SIDE, check_image
from .onnxmodel import check_pair, load_model, model_pair, shipped_model
from .siamfc import crop_square
from .state import damaged, read_array, read_flag, read_float, read_int, read_kernel

__all__ = ["EdgeTracker", "create", "model_paths", "pad_colour", "TUNABLE", "SHIPPED_NAME"]

SHIPPED_NAME = "edgetrack"
TUNABLE = ("instance_size", "lost_instance_size", "window_influence", "penalty_k", "size_lr",
           "score_threshold", "reacquire_threshold", "context_amount", "motion")
# Weight of the smoothed frame-to-frame motion added to the search centre (0: search at the last
# centre, the behaviour of models whose metadata predates it). Fast bodies cross a search
# region's half width (~120 px) in one frame; following them needs a prediction.
MOTION_SMOOTHING = 0.5
# Speeds below this share of the search region's side are the box's jitter, not motion: the
# prediction shrinks the smoothed motion by it (a soft dead zone). Without it, bodies drifting a
# few pixels per frame were tracked worse (calibration sequences: AO_2d -0.047 on one).
MOTION_DEAD_ZONE = 0.05
# While lost for more than this many frames, every other search sweeps the image (the wider lost
# region stepped over a grid, one crop per frame: latency stays one search): a body that moved
# far while the tracker was lost was otherwise never found again (a held-out sequence: lost for
# its last 22 frames with the body in view ~330 px from the last centre).
SWEEP_AFTER = 3
SWEEP_MIN_STEP = 8.0   # px: the sweep's cells are never closer (a search side of 10 px and more is unaffected)
# The frame after a re-acquisition ("settling") searches the wide lost region without the cosine
# window: the velocity is unknown then (a re-acquisition's jump is not motion), and a body that
# came back into view fast crossed the normal region in one frame (a held-out sequence: found at
# its return, lost the next frame ~150 px further, a chaotic fork between arithmetic variants).


def model_paths(name: str = SHIPPED_NAME) -> tuple[Path, Path]:
    """(template, search) paths of a shipped model."""
    return shipped_model(f"{name}_template.onnx"), shipped_model(f"{name}_search.onnx")


def pad_colour(value) -> tuple[float, float, float] | None:
    """A pad colour: None (the frame's mean colour) or three values in 0..255 (RGB), as a tuple of
    floats; anything else is a ValueError. The one check of it (metadata, caches, command line)."""
    if value is None:
        return None
    try:
        c = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        c = ()
    if len(c) != 3 or not all(0.0 <= v <= 255.0 for v in c):
        raise ValueError(f"pad must be three values in 0..255 (RGB), got {value!r}")
    return c


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def _change(r):
    # a degenerate candidate (zero width or height: r = 0) gets a huge, finite change, so its
    # penalty is 0 without a divide-by-zero warning (the fuzz run found one)
    r = np.maximum(r, 1e-12)
    return np.maximum(r, 1.0 / r)


class EdgeTracker:
    """EdgeTrack behind the Tracker2D seam: init(image, box), update(image) -> (ok, box), correct(box).

    Images are (H, W, 3) uint8 RGB; boxes [x, y, w, h] pixels. After each update `score` is
    the calibrated probability (0..1) that the chosen cell is on the target, `lost` whether
    the tracker considers the target gone (then update returned ok=False), and `timings_ms`
    the stage times (crop, net, post).
    """

    def __init__(self, template_model: str | Path, search_model: str | Path, threads: int = 1,
                 precision: str = "fp32", engine: str = "onnxruntime", **overrides):
        # each model a path or a model object (onnxmodel.load_model); precision / engine as
        # track3d.onnxmodel (variants chosen by measurement)
        arith = {"precision": precision, "engine": engine}
        self.template_net = load_model(template_model, threads, "edgetrack-template", **arith)
        self.search_net = load_model(search_model, threads, "edgetrack-search", **arith)
        # a template graph of another export makes kernels the search graph was not trained on
        check_pair(self.template_net, self.search_net, "track3d-train edgetrack export")
        meta = self.search_net.meta
        self.meta = meta
        unknown = set(overrides) - set(TUNABLE)
        if unknown:
            raise TypeError(f"unknown EdgeTrack options: {', '.join(sorted(unknown))} (tunable: {', '.join(TUNABLE)})")
        hp = dict(meta["tracking"])
        hp["instance_size"] = meta["instance_size"]
        hp["lost_instance_size"] = meta["lost_instance_size"]
        hp.update({k: v for k, v in overrides.items() if v is not None})
        self.exemplar_size = int(meta["exemplar_size"])
        self.stride = int(meta["total_stride"])
        self.instance_size = int(hp["instance_size"])
        self.lost_instance_size = int(hp["lost_instance_size"])
        for name in ("instance_size", "lost_instance_size"):
            v = getattr(self, name)
            if v < self.exemplar_size or v % self.stride:
                raise ValueError(f"{name} {v} must be >= {self.exemplar_size} and a multiple of the stride {self.stride}")
        self.window_influence = float(hp["window_influence"])
        self.penalty_k = float(hp["penalty_k"])
        self.size_lr = float(hp["size_lr"])
        self.score_threshold = float(hp["score_threshold"])
        # while lost, a candidate re-acquires the target only at this score or above (hysteresis;
        # models whose metadata predates it: the lost threshold itself). In the wide search just
        # after an exit the frame is mostly pad and sky, and the edge between them scored 0.74-0.88
        # on held-out sequences where the body was gone.
        self.reacquire_threshold = float(hp.get("reacquire_threshold", self.score_threshold))
        if not 0.0 < self.reacquire_threshold <= 1.0:
            raise ValueError(f"reacquire_threshold must be in (0, 1], got {self.reacquire_threshold}")
        self.context_amount = float(hp["context_amount"])
        self.motion = float(hp.get("motion", 0.0))
        if not 0.0 <= self.motion <= 2.0:
            raise ValueError(f"motion must be in 0..2, got {self.motion}")
        self.calib_a, self.calib_b = float(meta["score"]["a"]), float(meta["score"]["b"])
        self.pad = pad_colour(meta.get("pad"))
        self._grids = {}
        self._kernel = None
        self._max_side = float("inf")   # MAX_BOX_SCALE x the image, set by init()
        self._kshape = None      # the template kernel's shape, found on the first set_state
        self.score = float("nan")
        self.lost = False
        self.timings_ms: dict[str, float] = {}

    def _grid(self, size: int):
        """(cell centres (n,), cosine window (n, n)) of a search crop of `size` pixels."""
        g = self._grids.get(size)
        if g is None:
            n = size // self.stride
            centres = np.arange(n, dtype=np.float64) * self.stride + self.stride / 2.0
            h = np.hanning(n + 2)[1:-1]     # no zero weight on the border cells
            g = self._grids[size] = (centres, np.outer(h, h))
        return g

    # -- state -------------------------------------------------------------------------------
    def _set_box(self, box) -> None:
        b = np.asarray(box, dtype=np.float64).reshape(-1)
        if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
            raise ValueError(f"box must be [x, y, w, h], finite with positive size, got {b.tolist()}")
        # the centre held within MAX_BOX_SCALE x the image of it, as the size is: a corrected box
        # at y = 1e200 had made the next crop's map degenerate (a ValueError out of update)
        self.center = np.clip(b[:2] + b[2:] / 2.0, -self._max_side, self._max_side)
        # a (fused or corrected) state box beyond MAX_BOX_SCALE x the image is capped there, as
        # SiamFC's: a side of 1e200 overflowed the crop size to 0 (ZeroDivisionError in update);
        # a side below MIN_BOX_SIDE is raised to it (sides of 1e-182 x 1e-194 underflowed it)
        self.target_sz = np.clip(b[2:], MIN_BOX_SIDE, self._max_side)
        self._min_sz = max(2.0, 0.2 * float(self.target_sz.min()))

    def _z_sz(self) -> float:
        ctx = self.context_amount * self.target_sz.sum()
        return math.sqrt(float(np.prod(self.target_sz + ctx)))

    def init(self, image: np.ndarray, box) -> None:
        image = check_image(image)
        self._max_side = MAX_BOX_SCALE * max(image.shape[:2])
        self._set_box(box)
        # outside the image a crop is filled with the colour the model was trained with: one that
        # neither sky nor shadow takes tells the network where the image ends (models without
        # it in their metadata were trained with the frame's mean colour)
        self.avg_color = self.pad if self.pad is not None else tuple(float(c) for c in cv2.mean(image)[:3])
        z = crop_square(image, self.center, self._z_sz(), self.exemplar_size, self.avg_color)
        self._kernel = self.template_net.run({"template": z[None]})[0]
        self.velocity = np.zeros(2)
        self.lost_frames = 0
        self.settling = False
        self.lost = False
        self.score = 1.0

    def correct(self, box) -> None:
        """Adopt a new state box (e.g. the 2D-3D fused box): centre and size, same template."""
        if self._kernel is None:
            raise RuntimeError("correct() before init()")
        self._set_box(box)

    @property
    def box(self) -> np.ndarray:
        return np.concatenate([self.center - self.target_sz / 2.0, self.target_sz])

    def get_state(self) -> dict:
        """Everything the next update depends on, as numpy arrays and builtins (no ORT objects)."""
        if self._kernel is None:
            return {"initialised": False}
        return {"initialised": True, "kernel": self._kernel.copy(), "center": self.center.copy(),
                "target_sz": self.target_sz.copy(), "_min_sz": float(self._min_sz),
                "avg_color": list(self.avg_color), "score": float(self.score), "lost": bool(self.lost),
                "velocity": self.velocity.copy(), "lost_frames": int(self.lost_frames),
                "settling": bool(self.settling)}

    def _kernel_shape(self) -> tuple:
        """The template kernel's shape this model makes (from a blank template, once)."""
        if self._kshape is None:
            blank = np.zeros((1, self.exemplar_size, self.exemplar_size, 3), np.uint8)
            self._kshape = tuple(self.template_net.run({"template": blank})[0].shape)
        return self._kshape

    def set_state(self, state: dict) -> None:
        """Restore a `get_state()` of a tracker with the same models and hyper-parameters; a
        damaged one raises ValueError (one line) and leaves the tracker as it was."""
        with damaged("EdgeTrack"):
            if not read_flag(state.get("initialised"), "initialised"):
                self._kernel = None
                return
            kernel = read_kernel(state["kernel"], "template kernel", self._kernel_shape())
            center = read_array(state["center"], "center", (2,))
            target_sz = read_array(state["target_sz"], "target_sz", (2,), positive=True)
            avg_color = tuple(read_array(state["avg_color"], "avg_color", (3,)).tolist())
            score = read_float(state["score"], "score", nan_ok=True, inf_ok=True)
            lost, settling = read_flag(state["lost"], "lost"), read_flag(state.get("settling", False), "settling")
            min_sz = read_float(state["_min_sz"], "_min_sz", lo=0.0)
            # states written before the motion prediction carry no velocity: at rest
            velocity = read_array(state.get("velocity", (0.0, 0.0)), "velocity", (2,))
            lost_frames = read_int(state.get("lost_frames", 0), "lost_frames")
        # assigned only once everything parsed: a damaged state leaves the tracker as it was
        self._kernel, self.center, self.target_sz, self.avg_color = kernel, center, target_sz, avg_color
        self.score, self.lost, self._min_sz, self.velocity = score, lost, min_sz, velocity
        self.lost_frames, self.settling = lost_frames, settling

    def _lost_search_centre(self, side: float, ww: int, hh: int) -> np.ndarray:
        """Where a lost search looks: the last centre, and after SWEEP_AFTER lost frames, every
        other frame the next cell of a grid over the image (cells 0.8 search sides apart)."""
        k = self.lost_frames - SWEEP_AFTER
        if k <= 0 or k % 2 == 1:
            return self.center
        # cells at least SWEEP_MIN_STEP px apart, the cell found by its index: a list of every cell
        # of a sub-pixel target's grid had taken 0.6 s a frame and, smaller still, all the memory
        # (a latency walkthrough); for targets of a few pixels and more the same cells as before
        step = max(0.8 * side, SWEEP_MIN_STEP)
        xs = np.arange(side / 2.0, max(ww - side / 2.0, side / 2.0) + step, step)
        ys = np.arange(side / 2.0, max(hh - side / 2.0, side / 2.0) + step, step)
        i = (k // 2 - 1) % (len(xs) * len(ys))
        x, y = xs[i % len(xs)], ys[i // len(xs)]
        return np.array((min(x, ww - side / 2.0) if ww > side else ww / 2.0,
                         min(y, hh - side / 2.0) if hh > side else hh / 2.0), dtype=np.float64)

    def _predicted(self, side: float) -> np.ndarray:
        """The search centre's offset (2,) pixels for a search region of `side` image pixels."""
        speed = float(np.hypot(*self.velocity))
        dead = MOTION_DEAD_ZONE * side
        if speed <= dead:
            return np.zeros(2)
        return self.motion * (1.0 - dead / speed) * self.velocity

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        if self._kernel is None:
            raise RuntimeError("update() before init()")
        image = check_image(image)
        t0 = time.perf_counter()
        hh, ww = image.shape[:2]
        # a state restored or corrected without init() on this image size: the same cap
        self._max_side = MAX_BOX_SCALE * max(hh, ww)
        self.target_sz = np.minimum(self.target_sz, self._max_side)
        self.center = np.clip(self.center, -self._max_side, self._max_side)
        wide = self.lost or self.settling
        size = self.lost_instance_size if wide else self.instance_size
        scale = self.exemplar_size / self._z_sz()            # crop pixels per image pixel
        start = self.center
        # where the target should be now: the last centre moved by the smoothed motion
        if self.lost:
            at = self._lost_search_centre(size / scale, ww, hh)
        else:
            at = start if self.motion == 0.0 else np.clip(start + self._predicted(size / scale), 0.0, [ww, hh])
        crop = crop_square(image, at, size / scale, size, self.avg_color)
        t1 = time.perf_counter()
        logit, ltrb = self.search_net.run({"search": crop[None], "kernel": self._kernel})
        t2 = time.perf_counter()
        logit, ltrb = logit[0].astype(np.float64), ltrb[0].astype(np.float64)
        if not (np.all(np.isfinite(logit)) and np.all(np.isfinite(ltrb))):
            self.score, self.lost, self.velocity, self.settling = 0.0, True, np.zeros(2), False
            self.lost_frames += 1
            return False, self.box
        centres, window = self._grid(size)
        px, py = centres[None, :], centres[:, None]
        w, h = ltrb[0] + ltrb[2], ltrb[1] + ltrb[3]
        cx, cy = px + (ltrb[2] - ltrb[0]) / 2.0, py + (ltrb[3] - ltrb[1]) / 2.0
        tw, th = self.target_sz * scale
        pad = (w + h) / 2.0
        s_c = _change(np.sqrt((w + pad) * (h + pad)) / math.sqrt((tw + (tw + th) / 2) * (th + (tw + th) / 2)))
        r_c = _change((tw / th) / np.maximum(w / np.maximum(h, 1e-6), 1e-6))
        penalty = np.exp(-(r_c * s_c - 1.0) * self.penalty_k)
        prob = _sigmoid(logit)
        pscore = penalty * prob
        if not wide:
            pscore = pscore * (1.0 - self.window_influence) + window * self.window_influence
        i, j = np.unravel_index(int(np.argmax(pscore)), pscore.shape)
        self.score = float(_sigmoid(self.calib_a * logit[i, j] + self.calib_b))
        if self.score < (max(self.reacquire_threshold, self.score_threshold) if self.lost else self.score_threshold):
            # lost: the search stays where the target was last seen, without a motion guess
            self.lost, self.velocity, self.settling = True, np.zeros(2), False
            self.lost_frames += 1
            self.timings_ms = {"crop": 1e3 * (t1 - t0), "net": 1e3 * (t2 - t1), "post": 1e3 * (time.perf_counter() - t2)}
            return False, self.box
        was_tracking = not self.lost         # False: this frame re-acquires the target
        self.settling = not was_tracking
        self.lost, self.lost_frames = False, 0
        lr = float(penalty[i, j] * prob[i, j] * self.size_lr)
        self.center = np.clip(at + (np.array([cx[i, j], cy[i, j]]) - size / 2.0) / scale, 0.0, [ww, hh])
        new_sz = np.array([w[i, j], h[i, j]]) / scale
        self.target_sz = np.maximum((1.0 - lr) * self.target_sz + lr * new_sz, self._min_sz)
        if was_tracking:   # a re-acquisition's jump is not motion
            self.velocity = MOTION_SMOOTHING * self.velocity + (1.0 - MOTION_SMOOTHING) * (self.center - start)
        self.timings_ms = {"crop": 1e3 * (t1 - t0), "net": 1e3 * (t2 - t1), "post": 1e3 * (time.perf_counter() - t2)}
        return True, self.box


def create(threads: int = 1, model: str | Path | None = None, template_model: str | Path | None = None,
           search_model: str | Path | None = None, precision: str = "fp32", engine: str = "onnxruntime",
           **overrides) -> EdgeTracker:
    """An EdgeTrack tracker: the shipped model, or `model` a prefix `<dir>/<name>` of a pair
    `<name>_template.onnx` / `<name>_search.onnx`, or both explicit paths. Overrides: TUNABLE."""
    template_model, search_model = model_pair(model, template_model, search_model, ("template", "search"),
                                              model_paths)
    return EdgeTracker(template_model, search_model, threads=threads, precision=precision, engine=engine,
                       **overrides)
