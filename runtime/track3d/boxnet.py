"""A3BoxNet at run time (paper section IV-B): sampling, the ONNX session, decoding. No torch.

The network sees a fixed number N of points sampled from the frustum proposal (the C++
extension's sampler), translated by a reference point (the centroid for the paper's coding),
plus, for models trained with it, the one-hot coarse category. Its four heads decode as::

    centre = ref + dC1 + dC2
    size   = (template[cls] + residual[cls]) * L     or  E * (1 + residual[cls])   (per axis)

with cls = argmax(size scores). Which reference and which scale a model uses is its box
coding, named in its metadata (``size_norm``) and implemented once in `track3d.size_coding`
("points", "paper", "extent", "frustum"), which training and evaluation use as well.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .boxes import SIZE_TEMPLATES
from .frames import check_category, check_estimator_points, check_point_bounds, point_bounds
from .onnxmodel import ModelError, load_model, shipped_model
from .size_coding import SIZE_CODINGS, SizeCoding, size_coding

__all__ = [
    "KIND", "DEFAULT_MODEL", "NARROW_MODEL", "VIEWS_MODEL", "FULL_WIDTH_MODEL", "STEREO_FULL_WIDTH_MODEL", "SENSOR_MODELS", "model_for_sensor", "SIZE_NORMS",
    "BACKLIT_MODELS", "BACKLIT_PHASE_DEG", "backlit_model_for",
    "MAX_EXTENT_M", "INPUT_POINTS", "INPUT_CATEGORY", "OUTPUTS", "VIEWS", "SENSOR_VIEWS", "views_for", "MIRRORS",
    "PAST_VIEWS", "with_past_views", "one_hot", "average_boxes", "A3BoxNetEstimator", "create",
]

KIND = "a3boxnet"
# The half-width model (the default before VIEWS_MODEL): the full-width model (a3boxnet.onnx, the paper's widths) cut to half width and
# distilled from it (recipe a3boxnet-narrow; docs/models.md, "A narrower A3BoxNet"). Its network
# runs 3.5x faster on one core (the loop 1.7x on an AVX2-only CPU, where the full-width loop sat
# at 153 FPS); chosen on held-out sequences outside the README's sets: Track3D one pass level or
# better (held-out shapes +0.004 on 12, +0.010 AO_3d on 27 sequences). The full-width model stays
# shipped: the teacher, the stereo model's parent, and selectable as model="a3boxnet.onnx".
# Since then fine-tuned again, still distilled, with superquadric bodies in its training world
# (held-out shapes +0.006 to +0.015 AO_3d on the calibration sets, every README engine row up),
# then once more with Gaussian random spheres (mean +0.003 on seven calibration sets, six up).
NARROW_MODEL = "a3boxnet_narrow.onnx"
FULL_WIDTH_MODEL = "a3boxnet.onnx"
# The half-width model fine-tuned beside the body's past views (PAST_VIEWS; recipe a3boxnet-views):
# the loop gives it the views it has gathered of the body, in this frame, with each frustum. Mean
# AO_3d +0.004 with oracle 2D boxes and +0.007 with EdgeTrack in one pass on eight calibration
# splits (a control fine-tuned on the same frustums without the views was level: the gain is the
# views), every range-sensor row of the README's engine sets up; +0.4 ms a frame. The narrow model
# stays shipped: its parent, and the single-frame network (the paper's kind) as model=NARROW_MODEL.
VIEWS_MODEL = "a3boxnet_views.onnx"
DEFAULT_MODEL = VIEWS_MODEL
# Depth sensors with a model of their own. Block-matching stereo is another kind of cloud than a
# range sensor's: depth noise growing with z^2 (+-0.6 m per pixel at 30 m), smearing past the
# silhouette; the one model for every sensor saw it in 8% of its frustums and overestimated the
# hidden depth of noisy clouds. The stereo model is the full-width model fine-tuned on stereo
# bodies only (recipe a3boxnet-stereo; docs/models.md); every other sensor keeps the default.
# The loop runs it at half width, cut from it and distilled from it (recipe a3boxnet-stereo-narrow):
# 3.5x less network time, level or better on the stereo calibration sets (Track3D one pass +0.003
# AO_3d on six splits, ACE_3d lower on all six; oracle boxes level). The full-width stereo model
# stays shipped: the teacher, the back-lit model's parent, selectable as model=STEREO_FULL_WIDTH_MODEL.
STEREO_FULL_WIDTH_MODEL = "a3boxnet_stereo.onnx"
SENSOR_MODELS = {"stereo": "a3boxnet_stereo_narrow.onnx"}


def model_for_sensor(depth_sensor: str | None) -> Path:
    """The shipped A3BoxNet file for clouds of this depth sensor (None or unknown: the shared one)."""
    return shipped_model(SENSOR_MODELS.get(str(depth_sensor or "").lower(), DEFAULT_MODEL))


# Bodies lit from behind. Past 90 degrees of phase a stereo camera sees a crescent: depth only on
# the lit limb, the body's near side dark, its centre and depth hidden behind it (docs/models.md,
# "the hidden depth of crescents"). With the sun's direction known (Track3D.set_sun) and the phase
# at the 2D box past BACKLIT_PHASE_DEG, the estimator runs the sensor's back-lit model instead:
# the sensor's model fine-tuned on bodies lit from behind only (recipe a3boxnet-stereo-backlit).
# 100 rather than the outline share's 90 (sensor_options.SENSOR_OUTLINE_SHARE_PHASES): a body just past
# 90 degrees is still half lit, and there the sensor's own model did as well (chosen on the
# stereo calibration sets, docs/models.md); a body lit from the front never meets the model.
BACKLIT_MODELS = {"stereo": "a3boxnet_stereo_backlit.onnx"}
BACKLIT_PHASE_DEG = 100.0


def backlit_model_for(depth_sensor: str | None) -> Path | None:
    """The shipped A3BoxNet file for this sensor's bodies lit from behind, or None (none shipped)."""
    name = BACKLIT_MODELS.get(str(depth_sensor or "").lower())
    return None if name is None else shipped_model(name)


# Test-time views: the box is the average of `views` passes of the network over one frustum, view
# k with its own point sample (seed + k) and the cloud mirrored by MIRRORS[k % 4] about the
# optical axis (the net was trained with both mirrors; the principal point is the image centre),
# the box mirrored back; centres averaged, sizes by their geometric mean. One sample of N points
# from a frustum of thousands is one noisy look: its sampling and the net's asymmetries average
# out. VIEWS is the default; SENSOR_VIEWS per depth sensor (chosen by measurement, docs/models.md).
VIEWS = 1
SENSOR_VIEWS: dict[str, int] = {}
MIRRORS = ((), (0,), (1,), (0, 1))   # axes negated in view k % 4: none, x, y, both
MAX_VIEWS = 16


def views_for(depth_sensor: str | None) -> int:
    """The number of test-time views for clouds of this depth sensor (None or unknown: VIEWS)."""
    return SENSOR_VIEWS.get(str(depth_sensor or "").lower(), VIEWS)


def average_boxes(boxes: np.ndarray) -> np.ndarray:
    """(K, 6) boxes [cx, cy, cz, sx, sy, sz] -> (6,): centres averaged, sizes by their geometric mean
    (a size is a scale: 1 m and 4 m average to 2 m, as 0.5x and 2x of it)."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    return np.concatenate([b[:, :3].mean(axis=0), np.exp(np.log(b[:, 3:]).mean(axis=0))])


# The past views in the network's input (models whose metadata has ``past_views``): the frustum
# sampled to PAST_VIEWS["current"] points beside at most PAST_VIEWS["past"] of the body's past
# views in this frame (track3d.body_views.BodyViews.past_points), the network's N points then
# sampled from both. The body turns while the loop watches it, so the side hidden now was in view
# before; a single-frame net guesses it, a net given the past views sees part of it. A fixed
# share (3 : 1), not the clouds' own sizes: a near body's 40,000 returns would drown the views.
PAST_VIEWS = {"current": 1536, "past": 512}


def with_past_views(points: np.ndarray, past: np.ndarray | None, seed: int,
                    counts: dict | None = None) -> np.ndarray:
    """The input cloud of a past-views model: points (n, 3), n >= 1, sampled to counts["current"]
    and past (m, 3) sampled to min(m, counts["past"]), stacked (float32); `points` as they are
    when `past` is None or empty."""
    from .frustum import sample_points

    c = PAST_VIEWS if counts is None else counts
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if past is None or len(past) == 0:
        return pts
    cur = sample_points(pts, int(c["current"]), seed)
    old = sample_points(np.ascontiguousarray(past, dtype=np.float32), min(len(past), int(c["past"])), seed + 1)
    return np.concatenate([cur, old])


SIZE_NORMS = tuple(SIZE_CODINGS)   # the box codings a model's metadata may name (track3d.size_coding)
# ONNX interface: inputs and outputs by name (batch dimension dynamic).
INPUT_POINTS = "points"        # (B, N, 3) float32, minus the coding's reference point
INPUT_CATEGORY = "category"    # (B, C) float32 one-hot coarse category (absent without category)
OUTPUTS = ("center1", "center2", "size_scores", "size_residuals")  # (B,3) (B,3) (B,14) (B,14,3)
# metres: the largest extent of the sampled points A3BoxNet answers for. The frustum of the
# paper's 1..45 m crop is at most 44 m deep; on point sets spanning hundreds of metres the net
# (trained on asteroids of a few metres) returned boxes 200-3000x their extent (measured).
MAX_EXTENT_M = 60.0


def one_hot(category, num_categories: int) -> np.ndarray:
    """Coarse category index (or indices) -> float32 one-hot; an unknown category (-1) gives zeros."""
    try:
        c = np.asarray(category, dtype=np.int64)
    except (OverflowError, TypeError, ValueError):
        raise ValueError(f"category must be integers in -1..{num_categories - 1}, got {category!r}") from None
    if np.any((c < -1) | (c >= num_categories)):
        raise ValueError(f"category must be in -1..{num_categories - 1}, got {category}")
    flat = c.reshape(-1)
    out = np.zeros((len(flat), num_categories), dtype=np.float32)
    known = np.nonzero(flat >= 0)[0]
    out[known, flat[known]] = 1.0
    return out.reshape(c.shape + (num_categories,))


def _check_phase(value, what: str = "phase_deg must be degrees in 0..180 or None") -> float:
    """A phase angle in degrees, 0..180, as a float; ValueError `what` otherwise (NaN, a bool, an array)."""
    if isinstance(value, (bool, np.bool_)) or np.ndim(value) != 0:
        raise ValueError(f"{what}, got {value!r:.80}")
    try:
        ph = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}, got {value!r:.80}") from None
    if not 0.0 <= ph <= 180.0:
        raise ValueError(f"{what}, got {value!r:.80}")
    return ph


def _made_for(meta: dict, depth_sensor: str | None) -> bool:
    """Whether a model's metadata names `depth_sensor` as the sensor it was trained for."""
    made = str(meta.get("depth_sensor") or "").lower()
    return bool(made) and made == str(depth_sensor or "").lower()


class A3BoxNetEstimator:
    """The box estimator behind the loop's seam: ``estimate(points (n,3), category) -> (6,)``.

    model: path of an exported A3BoxNet ONNX file (default: the shipped one for `depth_sensor`,
    see SENSOR_MODELS; an explicit model wins);
    threads: onnxruntime intra-op threads; num_points: override of the model's N (only for
    models exported with a dynamic point axis, which ours are); seed: the sampling seed, fixed
    per call so that the same points always give the same box (deterministic); precision /
    engine: the model variant ("fp32" | "int8" | "bf16" | "auto", "onnxruntime" | "openvino" |
    "auto", see track3d.onnxmodel; the choice is in ``.model.choice``); views: test-time views
    averaged per box, 1..16 (default: `views_for(depth_sensor)`; see VIEWS), run as one batch;
    backlit_model: the model for frames whose phase angle (``estimate(..., phase_deg=)``) is past
    `backlit_phase` degrees (default: the sensor's, BACKLIT_MODELS, unless `model` is given and
    its metadata names another sensor or none; it runs with this estimator's other options, in
    ``.backlit``); backlit_phase: that gate,
    0..180 (180: never); past_views: False runs a model trained beside the body's past views
    (metadata ``past_views``, PAST_VIEWS) on the frustum alone (``takes_past`` then False; a model
    without them never takes them).
    """

    name = KIND
    # estimate() takes the loop's frustum bounds (Track3D passes them: no second pass over the points)
    takes_bounds = True
    # estimate() reads the phase angle at the 2D box (the loop passes it with the sun known) only
    # with a back-lit model; set per instance, so that the loop computes no phase it would not use
    takes_phase = False
    # a guess of the whole body: the loop keeps its hidden back face and measures the rest
    amodal = True
    # estimate() reads the body's past views (past=) only with a model trained with them; per instance
    takes_past = False

    def __init__(self, model: str | Path | None = None, threads: int = 1, num_points: int | None = None,
                 seed: int = 0, precision: str = "fp32", engine: str = "onnxruntime",
                 depth_sensor: str | None = None, views: int | None = None,
                 backlit_model: str | Path | None = None, backlit_phase: float = BACKLIT_PHASE_DEG,
                 past_views: bool = True):
        self.backlit_phase = _check_phase(backlit_phase, "backlit_phase must be degrees in 0..180")
        # the caller's numbers first: a bad one must not read as a damaged model (it had been
        # "A3BoxNet metadata is incomplete" for num_points=abc)
        for key, value, low in (("num_points", num_points, 1), ("threads", threads, 1), ("seed", seed, 0)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                      or value < low):
                raise ValueError(f"{key} must be an integer >= {low}, got {value!r}")
        explicit = model is not None
        if views is None:
            views = views_for(depth_sensor)
        if isinstance(views, bool) or not isinstance(views, (int, np.integer)) or not 1 <= views <= MAX_VIEWS:
            raise ValueError(f"views must be an integer in 1..{MAX_VIEWS}, got {views!r}")
        self.views = int(views)
        if model is None:
            model = model_for_sensor(depth_sensor)
        # a path or a model object (onnxmodel.load_model)
        self.model = load_model(model, threads, KIND, precision, engine)
        meta = self.model.meta
        try:
            self.num_points = int(num_points or meta["num_points"])
            self.num_categories = int(meta["num_categories"])
            self.use_category = bool(meta.get("use_category", True))
            self.size_norm = str(meta.get("size_norm", "points"))
            self.coding: SizeCoding = size_coding(self.size_norm)
            templates = np.asarray(meta["size_templates"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ModelError(f"{self.model.path}: A3BoxNet metadata is incomplete ({e})") from None
        if templates.shape != SIZE_TEMPLATES.shape or not np.allclose(templates, SIZE_TEMPLATES, atol=1e-6):
            raise ModelError(f"{self.model.path}: its size-class table differs from track3d.boxes.SIZE_TEMPLATES")
        if self.num_points < 1:
            raise ValueError(f"num_points must be >= 1, got {self.num_points}")
        self.seed = int(seed)
        self.threads = int(threads)
        self.meta = meta
        names = set(self.model.input_names)
        if INPUT_POINTS not in names or (self.use_category and INPUT_CATEGORY not in names):
            raise ModelError(f"{self.model.path}: inputs {sorted(names)} are not an A3BoxNet's")
        self._with_category = INPUT_CATEGORY in names
        # a model trained beside the body's past views (PAST_VIEWS) takes them: the loop passes past=
        if not isinstance(past_views, (bool, np.bool_)):
            raise ValueError(f"past_views must be True or False, got {past_views!r:.80}")
        self.past_views: dict | None = None
        if meta.get("past_views") and past_views:
            pv = meta["past_views"]
            try:
                self.past_views = {"current": int(pv["current"]), "past": int(pv["past"])}
            except (KeyError, TypeError, ValueError):
                raise ModelError(f"{self.model.path}: its past_views metadata is not {{current, past}} counts") from None
            self.takes_past = True
        # An explicit model keeps the sensor's back-lit model only when it is itself that sensor's
        # model (its metadata says so): the full-width stereo model chosen by hand lost the gate.
        if (backlit_model is None and self.backlit_phase < 180.0
                and (not explicit or _made_for(meta, depth_sensor))):
            backlit_model = backlit_model_for(depth_sensor)
        self.backlit: A3BoxNetEstimator | None = None
        if backlit_model is not None and self.backlit_phase < 180.0:
            self.backlit = A3BoxNetEstimator(backlit_model, threads, num_points, seed, precision, engine,
                                             views=views, backlit_phase=180.0)
            if self.backlit.use_category != self.use_category or self.backlit.size_norm != self.size_norm:
                raise ModelError(f"{self.backlit.model.path}: its category input or box coding differs from "
                                 f"{self.model.path.name}'s")
            # held here too, so that run records (Track3D.describe) and network timings see it
            self.backlit_net = self.backlit.model
            self.takes_phase = True

    def __repr__(self) -> str:
        v = f", views={self.views}" if self.views != 1 else ""
        b = (f", backlit={self.backlit.model.path.name} past {self.backlit_phase:g} deg"
             if self.backlit is not None else "")
        return f"A3BoxNetEstimator({self.model.path.name}, N={self.num_points}, threads={self.threads}{v}{b})"

    def sample(self, points: np.ndarray, view: int = 0) -> np.ndarray:
        """The N points view `view` sees (sampling seed + view; not mirrored)."""
        from .frustum import sample_points

        return sample_points(np.ascontiguousarray(points, dtype=np.float32), self.num_points, self.seed + view)

    def infer(self, centred: np.ndarray, category) -> list[np.ndarray]:
        """Raw network outputs for a batch of centred points (B, N, 3) and categories (B,)."""
        feeds = {INPUT_POINTS: np.ascontiguousarray(centred, dtype=np.float32)}
        if self._with_category:
            feeds[INPUT_CATEGORY] = one_hot(np.reshape(category, (-1,)), self.num_categories)
        return self.model.run(feeds, list(OUTPUTS))

    def estimate(self, points: np.ndarray, category: int, bounds: np.ndarray | None = None,
                 phase_deg: float | None = None, past: np.ndarray | None = None) -> np.ndarray:
        """Frustum points (n, 3) float32, n >= 1, and the coarse category -> box (6,) float64.

        bounds: (2, 3) [min; max] of the points, if the caller has them (the loop's frustum pass
        does); computed here otherwise, and only by codings that read them (``coding.needs_bounds``).
        phase_deg: the phase angle at the 2D box (track3d.dark_side.phase_deg) when the sun is
        known, else None; past `backlit_phase` the back-lit model answers (``.backlit``).
        past: the body's past views in this frame (m, 3) (track3d.body_views.BodyViews.past_points)
        or None; read by models trained with them (``past_views``, `with_past_views`), ignored by others.
        Raises ValueError on points, bounds or a category outside the contract (track3d.frames).
        The values are checked on the sample the network sees (N points) and on the bounds (the
        caller's, or the points' own when none are given), not point by point over the frustum."""
        if phase_deg is not None and _check_phase(phase_deg) > self.backlit_phase and self.backlit is not None:
            return self.backlit.estimate(points, category, bounds)
        category = check_category(category, self.num_categories)
        pts = check_estimator_points(points, finite=False)
        # Every point's values, not only the sampled ones', through the enclosing boxes: a cloud
        # with four nan coordinates the sample missed had been boxed as if they were not there
        # (fuzz seed 83). The loop passes its frustum pass's bounds and views it made from that
        # frustum, so only a caller without bounds pays the pass (60 us on 46,000 points).
        own = bounds is None
        if own:
            bounds = np.stack(point_bounds(pts)).astype(np.float64)
            check_point_bounds(bounds[0], bounds[1])
        if self.past_views is not None and past is not None and len(past):
            views = check_estimator_points(past, finite=False)
            if own:
                check_point_bounds(*point_bounds(views))
            pts = with_past_views(pts, views, self.seed, self.past_views)
            bounds = None   # those of the frustum alone do not enclose the views
        sample = self.sample(pts) if self.views == 1 else np.stack([self.sample(pts, k) for k in range(self.views)])
        lo, hi = point_bounds(sample.reshape(-1, 3))
        check_point_bounds(lo, hi)
        if float(np.max(hi.astype(np.float64) - lo)) > MAX_EXTENT_M:
            raise ValueError(f"A3BoxNet answers for points spanning at most {MAX_EXTENT_M:g} m, "
                             f"these span {float(np.max(hi.astype(np.float64) - lo)):.3g} m")
        if self.coding.needs_bounds:
            bounds = self._check_bounds(pts, bounds, lo, hi)
        if self.views == 1:
            centred, ref, scale = self.coding.normalise(sample[None], None if bounds is None else bounds[None])
            return self.coding.decode(ref, scale, *self.infer(centred, [category]))[0]
        return self._estimate_views(sample, category, bounds)

    def _estimate_views(self, samples: np.ndarray, category: int, bounds: np.ndarray | None) -> np.ndarray:
        """samples: (K, N, 3), view k unmirrored -> the averaged box (6,)."""
        k_views = len(samples)
        sign = np.ones((k_views, 3))
        for k in range(k_views):
            sign[k, list(MIRRORS[k % len(MIRRORS)])] = -1.0
        mirrored = samples * sign[:, None, :].astype(np.float32)
        b = None
        if bounds is not None:
            # negating an axis swaps its min and max
            lo, hi = bounds[0] * sign, bounds[1] * sign
            b = np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], axis=1)
        centred, ref, scale = self.coding.normalise(mirrored, b)
        boxes = self.coding.decode(ref, scale, *self.infer(centred, [category] * k_views))
        boxes[:, :3] *= sign
        return average_boxes(boxes)

    @staticmethod
    def _check_bounds(pts: np.ndarray, bounds, sample_lo: np.ndarray, sample_hi: np.ndarray) -> np.ndarray:
        if bounds is None:
            b = np.stack(point_bounds(pts)).astype(np.float64)
        else:
            try:
                b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
            except (TypeError, ValueError):
                raise ValueError(f"bounds must be (2, 3) numbers [min; max], got {bounds!r:.80}") from None
        check_point_bounds(b[0], b[1])
        # the bounds of these points enclose their sample; anything else is another point set's
        if np.any(b[0] > sample_lo) or np.any(b[1] < sample_hi):
            raise ValueError("bounds do not enclose the points: pass the [min; max] of these points")
        if float(np.max(b[1, :2] - b[0, :2])) > MAX_EXTENT_M:
            raise ValueError(f"A3BoxNet answers for points spanning at most {MAX_EXTENT_M:g} m, "
                             f"these span {float(np.max(b[1, :2] - b[0, :2])):.3g} m across the line of sight")
        return b


def create(**options) -> A3BoxNetEstimator:
    """Factory of the estimator registry (`track3d.estimators`, name "a3boxnet")."""
    return A3BoxNetEstimator(**options)
