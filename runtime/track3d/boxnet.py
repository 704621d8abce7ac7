"""A3BoxNet at run time (paper section IV-B): sampling, the ONNX session, decoding. No torch.

The network sees a fixed number N of points sampled from the frustum proposal (the C++
extension's sampler), made translation invariant by subtracting their centroid, plus the
one-hot coarse category. Its four heads are decoded here, the ONE implementation used by
the runtime, by training (labels) and by evaluation::

    centre = centroid + dC1 + dC2
    size   = (template[cls] + residual[cls]) * L,   cls = argmax(size scores)

L, the remapping length of the paper, is the largest extent of the enclosing box of the
sampled points (``remap_length``). Two codings of the size-residual label exist
(model metadata ``size_norm``):

- ``"points"`` (default, ours): the label is ``size / L - template[cls]``, with L from the
  same input points, so training and decoding use the same length;
- ``"paper"`` (the paper's Appendix B): the label is ``size / max(size) - template[cls]``
  while decoding multiplies by L from the points. When the points see only part of the
  object (always: the far side is hidden), L < max(size) and the decoded size is biased;
- ``"extent"`` (ours, per axis): ``size = E * (1 + residual[cls])`` with E the extent of the
  points' enclosing box along x, y, z (``remap_extent``). The visible surface already spans
  nearly the whole body across the line of sight (measured: the points' x / y extents are
  3-4% short of the truth, a net regressing template + residual * L is 10-13% off), so the
  net only learns a small correction there and the hidden depth along z. The class head
  is kept: it picks which of the 14 residuals applies.

In both codings the size class is the template nearest to ``size / max(size)``
(``track3d.boxes.size_class_of``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .boxes import NUM_SIZE_CLASSES, SIZE_TEMPLATES, decode_size, size_class_of
from .frames import check_category, check_estimator_points, check_point_bounds, point_bounds
from .onnxmodel import ModelError, load_model, shipped_model

__all__ = [
    "KIND", "DEFAULT_MODEL", "SIZE_NORMS", "MAX_EXTENT_M", "INPUT_POINTS", "INPUT_CATEGORY", "OUTPUTS",
    "remap_length", "remap_extent", "normalise", "one_hot", "size_labels", "decode", "decode_batch",
    "A3BoxNetEstimator", "create",
]

KIND = "a3boxnet"
DEFAULT_MODEL = "a3boxnet.onnx"
SIZE_NORMS = ("points", "paper", "extent")
# ONNX interface: inputs and outputs by name (batch dimension dynamic).
INPUT_POINTS = "points"        # (B, N, 3) float32, centroid-subtracted
INPUT_CATEGORY = "category"    # (B, C) float32 one-hot coarse category (absent without category)
OUTPUTS = ("center1", "center2", "size_scores", "size_residuals")  # (B,3) (B,3) (B,14) (B,14,3)
_MIN_LENGTH = 1e-3             # metres: L of a degenerate point set (one point, a line)
# metres: the largest extent of the sampled points A3BoxNet answers for. The frustum of the
# paper's 1..45 m crop is at most 44 m deep; on point sets spanning hundreds of metres the net
# (trained on asteroids of a few metres) returned boxes 200-3000x their extent (measured).
MAX_EXTENT_M = 60.0


def remap_length(points: np.ndarray) -> np.ndarray:
    """L: the largest extent of the axis-aligned enclosing box of the points.

    points (..., N, 3) -> (...) float64, floored at 1 mm so a degenerate set cannot divide by 0."""
    p = np.asarray(points, dtype=np.float64)
    ext = p.max(axis=-2) - p.min(axis=-2)
    return np.maximum(ext.max(axis=-1), _MIN_LENGTH)


def remap_extent(points: np.ndarray) -> np.ndarray:
    """E: the extents of the points' axis-aligned enclosing box, (..., N, 3) -> (..., 3) float64,
    each floored at 10% of the largest (and 1 mm), so a flat or thin cut cannot divide by ~0."""
    p = np.asarray(points, dtype=np.float64)
    ext = p.max(axis=-2) - p.min(axis=-2)
    return np.maximum(ext, 0.1 * np.maximum(ext.max(axis=-1, keepdims=True), _MIN_LENGTH))


def normalise(points: np.ndarray, size_norm: str = "points") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sampled points (..., N, 3) -> (centred float32 points, centroid (..., 3) float64, the size
    scale: L (...) for the "points" and "paper" codings, E (..., 3) for "extent")."""
    p = np.asarray(points, dtype=np.float64)
    centroid = p.mean(axis=-2)
    scale = remap_extent(p) if size_norm == "extent" else remap_length(p)
    return (p - centroid[..., None, :]).astype(np.float32), centroid, scale


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


def size_labels(size: np.ndarray, length: np.ndarray, size_norm: str = "points"):
    """Training labels of the size head: (cls (...,) int64, residual (..., 3), scale (...)).

    The residual is normalised: the net predicts it and ``decode`` multiplies by L. ``scale``
    is the length that turns a normalised residual error into metres (the loss of Appendix B:
    gamma = |R - r * max(S)|): max(size) for "paper", L for "points", E (..., 3) for "extent"
    (``length`` is then the points' extents, see ``normalise``).
    """
    s = np.asarray(size, dtype=np.float64)
    cls, res = size_class_of(s)
    if size_norm == "extent":
        e = np.asarray(length, dtype=np.float64)
        return cls, s / e - 1.0, e
    if size_norm == "paper":
        return cls, res, s.max(axis=-1)
    if size_norm == "points":
        length = np.asarray(length, dtype=np.float64)
        return cls, s / length[..., None] - SIZE_TEMPLATES[cls], length
    raise ValueError(f"size_norm must be one of {SIZE_NORMS}, got {size_norm!r}")


def decode_batch(centroid, length, center1, center2, size_scores, size_residuals,
                 size_norm: str = "points") -> np.ndarray:
    """Network outputs of a batch -> (B, 6) boxes [cx, cy, cz, sx, sy, sz] (float64).
    length: L (B,), or the extents E (B, 3) for the "extent" coding."""
    scores = np.asarray(size_scores, dtype=np.float64)
    res = np.asarray(size_residuals, dtype=np.float64).reshape(len(scores), NUM_SIZE_CLASSES, 3)
    cls = scores.argmax(axis=-1)
    r = res[np.arange(len(cls)), cls]
    center = np.asarray(centroid, np.float64) + np.asarray(center1, np.float64) + np.asarray(center2, np.float64)
    if size_norm == "extent":
        size = np.asarray(length, dtype=np.float64).reshape(-1, 3) * (1.0 + r)
    else:
        size = decode_size(cls, r, np.asarray(length, dtype=np.float64))
    # a size can never be negative; a (rare) residual beyond the template is clamped to 1 mm
    return np.concatenate([center, np.maximum(size, _MIN_LENGTH)], axis=-1)


def decode(centroid, length, center1, center2, size_scores, size_residuals, size_norm: str = "points") -> np.ndarray:
    """One sample's outputs (batch of 1 or unbatched) -> (6,) box."""
    scale = np.reshape(length, (1, 3) if size_norm == "extent" else (1,))
    return decode_batch(np.reshape(centroid, (1, 3)), scale, np.reshape(center1, (1, 3)),
                        np.reshape(center2, (1, 3)), np.reshape(size_scores, (1, -1)),
                        np.reshape(size_residuals, (1, -1, 3)), size_norm)[0]


class A3BoxNetEstimator:
    """The box estimator behind the loop's seam: ``estimate(points (n,3), category) -> (6,)``.

    model: path of an exported A3BoxNet ONNX file (default: the shipped one);
    threads: onnxruntime intra-op threads; num_points: override of the model's N (only for
    models exported with a dynamic point axis, which ours are); seed: the sampling seed, fixed
    per call so that the same points always give the same box (deterministic); precision /
    engine: the model variant ("fp32" | "int8" | "bf16" | "auto", "onnxruntime" | "openvino" |
    "auto", see track3d.onnxmodel; the choice is in ``.model.choice``).
    """

    name = KIND

    def __init__(self, model: str | Path | None = None, threads: int = 1, num_points: int | None = None,
                 seed: int = 0, precision: str = "fp32", engine: str = "onnxruntime"):
        if model is None:
            model = shipped_model(DEFAULT_MODEL)
        # a path or a model object (onnxmodel.load_model)
        self.model = load_model(model, threads, KIND, precision, engine)
        meta = self.model.meta
        try:
            self.num_points = int(num_points or meta["num_points"])
            self.num_categories = int(meta["num_categories"])
            self.use_category = bool(meta.get("use_category", True))
            self.size_norm = str(meta.get("size_norm", "points"))
            templates = np.asarray(meta["size_templates"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ModelError(f"{path}: A3BoxNet metadata is incomplete ({e})") from None
        if templates.shape != SIZE_TEMPLATES.shape or not np.allclose(templates, SIZE_TEMPLATES, atol=1e-6):
            raise ModelError(f"{path}: its size-class table differs from track3d.boxes.SIZE_TEMPLATES")
        if self.size_norm not in SIZE_NORMS:
            raise ModelError(f"{path}: unknown size coding {self.size_norm!r} (known: {', '.join(SIZE_NORMS)})")
        if self.num_points < 1:
            raise ValueError(f"num_points must be >= 1, got {self.num_points}")
        self.seed = int(seed)
        self.threads = int(threads)
        self.meta = meta
        names = set(self.model.input_names)
        if INPUT_POINTS not in names or (self.use_category and INPUT_CATEGORY not in names):
            raise ModelError(f"{path}: inputs {sorted(names)} are not an A3BoxNet's")
        self._with_category = INPUT_CATEGORY in names

    def __repr__(self) -> str:
        return f"A3BoxNetEstimator({self.model.path.name}, N={self.num_points}, threads={self.threads})"

    def sample(self, points: np.ndarray) -> np.ndarray:
        from .frustum import sample_points

        return sample_points(np.ascontiguousarray(points, dtype=np.float32), self.num_points, self.seed)

    def infer(self, centred: np.ndarray, category) -> list[np.ndarray]:
        """Raw network outputs for a batch of centred points (B, N, 3) and categories (B,)."""
        feeds = {INPUT_POINTS: np.ascontiguousarray(centred, dtype=np.float32)}
        if self._with_category:
            feeds[INPUT_CATEGORY] = one_hot(np.reshape(category, (-1,)), self.num_categories)
        return self.model.run(feeds, list(OUTPUTS))

    def estimate(self, points: np.ndarray, category: int) -> np.ndarray:
        """Frustum points (n, 3) float32, n >= 1, and the coarse category -> box (6,) float64.

        Raises ValueError on points or a category outside the contract (track3d.frames). The
        values are checked on the sample the network sees (N points), not on the whole frustum."""
        category = check_category(category, self.num_categories)
        pts = check_estimator_points(points, finite=False)
        sample = self.sample(pts)
        lo, hi = point_bounds(sample)
        check_point_bounds(lo, hi)
        if float(np.max(hi.astype(np.float64) - lo)) > MAX_EXTENT_M:
            raise ValueError(f"A3BoxNet answers for points spanning at most {MAX_EXTENT_M:g} m, "
                             f"these span {float(np.max(hi.astype(np.float64) - lo)):.3g} m")
        centred, centroid, scale = normalise(sample, self.size_norm)
        out = self.infer(centred[None], [category])
        return decode(centroid, scale, *out, size_norm=self.size_norm)


def create(**options) -> A3BoxNetEstimator:
    """Factory of the estimator registry (`track3d.estimators`, name "a3boxnet")."""
    return A3BoxNetEstimator(**options)
