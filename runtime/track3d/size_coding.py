"""A3BoxNet's box codings: how points are normalised, how labels are coded, how outputs decode.

One object per coding, chosen by the model metadata's name (``size_norm``); the runtime,
training (labels), evaluation and quantisation all use the same object, so a coding is
written once. Every coding translates the sampled points by a reference point ``ref`` and
decodes ``centre = ref + center1 + center2``; they differ in the reference and in the size
scale:

- ``"points"`` (ours): ref = centroid of the sampled points; L = the largest extent of
  their enclosing box; label ``size / L - template[cls]``; ``size = (template + r) * L``.
- ``"paper"`` (the paper's Appendix B): as "points", but the label is
  ``size / max(size) - template[cls]`` while decoding multiplies by L. The points never see
  the hidden far side, so L < max(size) and the decoded size is biased.
- ``"extent"`` (ours, per axis): ref = centroid; E = the extents of the sampled points'
  enclosing box along x, y, z; ``size = E * (1 + r)``.
- ``"frustum"`` (ours, per axis, the whole frustum): the x and y extents and the x / y
  reference come from the enclosing box of ALL frustum points (the loop's C++ frustum pass
  computes it for free), z from the sample as in "extent". Measured on the engine test split
  (ideal depth, oracle 2D): the 512-point sample's x / y extents are 4.5% short of the body
  with 0.09 / 0.08 m centre error, the whole frustum's 1% short with 0.06 / 0.05 m, which a
  net cannot recover from the sample. z stays on the sample: a stereo frustum's depth range
  holds mismatched points up to 6x the body's depth.

The size class is always the template nearest to ``size / max(size)``
(``track3d.boxes.size_class_of``); every decoded size is floored at 1 mm.
"""
from __future__ import annotations

import numpy as np

from .boxes import SIZE_TEMPLATES, decode_size, size_class_of

__all__ = ["SizeCoding", "SIZE_CODINGS", "size_coding", "remap_length", "remap_extent", "MIN_LENGTH"]

MIN_LENGTH = 1e-3   # metres: L of a degenerate point set (one point, a line); the smallest size


def remap_length(points: np.ndarray) -> np.ndarray:
    """L: the largest extent of the axis-aligned enclosing box of the points.

    points (..., N, 3) -> (...) float64, floored at 1 mm so a degenerate set cannot divide by 0."""
    p = np.asarray(points, dtype=np.float64)
    ext = p.max(axis=-2) - p.min(axis=-2)
    return np.maximum(ext.max(axis=-1), MIN_LENGTH)


def _floor_extent(ext: np.ndarray) -> np.ndarray:
    return np.maximum(ext, 0.1 * np.maximum(ext.max(axis=-1, keepdims=True), MIN_LENGTH))


def remap_extent(points: np.ndarray) -> np.ndarray:
    """E: the extents of the points' axis-aligned enclosing box, (..., N, 3) -> (..., 3) float64,
    each floored at 10% of the largest (and 1 mm), so a flat or thin cut cannot divide by ~0."""
    p = np.asarray(points, dtype=np.float64)
    return _floor_extent(p.max(axis=-2) - p.min(axis=-2))


class SizeCoding:
    """Base of the codings. Shapes: points (..., N, 3); bounds (..., 2, 3) [min; max] of the
    whole frustum (only codings with ``needs_bounds`` read them); ref (..., 3) float64; scale
    (...) for the length codings, (..., 3) for the per-axis ones."""

    name = ""
    per_axis = False
    needs_bounds = False
    description = ""

    def __repr__(self) -> str:
        return f"size_coding({self.name!r})"

    def reference(self, p: np.ndarray, bounds) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def normalise(self, points: np.ndarray, bounds: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sampled points -> (points minus ref, float32; ref; scale)."""
        p = np.asarray(points, dtype=np.float64)
        if self.needs_bounds:
            if bounds is None:
                raise ValueError(f"the {self.name!r} coding needs the frustum's bounds (..., 2, 3)")
            bounds = np.asarray(bounds, dtype=np.float64)
            if bounds.shape != p.shape[:-2] + (2, 3):
                raise ValueError(f"bounds must have shape {p.shape[:-2] + (2, 3)}, got {bounds.shape}")
        ref, scale = self.reference(p, bounds)
        return (p - ref[..., None, :]).astype(np.float32), ref, scale

    def labels(self, size: np.ndarray, scale: np.ndarray):
        """Training labels of the size head: (cls (...,) int64, residual (..., 3), loss scale).
        The loss scale turns a residual error into metres (Appendix B: gamma = |R - r * scale|)."""
        raise NotImplementedError

    def sizes(self, cls: np.ndarray, r: np.ndarray, scale: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def decode(self, ref, scale, center1, center2, size_scores, size_residuals) -> np.ndarray:
        """Network outputs of a batch -> (B, 6) boxes [cx, cy, cz, sx, sy, sz] float64."""
        scores = np.asarray(size_scores, dtype=np.float64)
        scores = scores.reshape(-1, scores.shape[-1])
        res = np.asarray(size_residuals, dtype=np.float64).reshape(len(scores), len(SIZE_TEMPLATES), 3)
        cls = scores.argmax(axis=-1)
        r = res[np.arange(len(cls)), cls]
        centre = (np.asarray(ref, np.float64).reshape(-1, 3) + np.asarray(center1, np.float64).reshape(-1, 3)
                  + np.asarray(center2, np.float64).reshape(-1, 3))
        scale = np.asarray(scale, dtype=np.float64).reshape((-1, 3) if self.per_axis else (-1,))
        # a size can never be negative; a (rare) residual beyond the template is clamped to 1 mm
        return np.concatenate([centre, np.maximum(self.sizes(cls, r, scale), MIN_LENGTH)], axis=-1)


class _LengthCoding(SizeCoding):
    def reference(self, p, bounds):
        return p.mean(axis=-2), remap_length(p)

    def sizes(self, cls, r, scale):
        return decode_size(cls, r, scale)


class PointsCoding(_LengthCoding):
    name = "points"
    description = ("points minus their centroid (float32); centre = centroid + center1 + center2; "
                   "L = largest extent of the enclosing box of the sampled points; "
                   "size = (template[argmax scores] + residual[argmax]) * L")

    def labels(self, size, scale):
        s = np.asarray(size, dtype=np.float64)
        length = np.asarray(scale, dtype=np.float64)
        cls, _ = size_class_of(s)
        return cls, s / length[..., None] - SIZE_TEMPLATES[cls], length


class PaperCoding(_LengthCoding):
    name = "paper"
    description = PointsCoding.description + " (labels normalised by max(size))"

    def labels(self, size, scale):
        s = np.asarray(size, dtype=np.float64)
        cls, res = size_class_of(s)
        return cls, res, s.max(axis=-1)


class ExtentCoding(SizeCoding):
    name = "extent"
    per_axis = True
    description = ("points minus their centroid (float32); centre = centroid + center1 + center2; "
                   "E = per-axis extents of the enclosing box of the sampled points, each floored at 10% "
                   "of the largest; size = E * (1 + residual[argmax scores])")

    def reference(self, p, bounds):
        return p.mean(axis=-2), remap_extent(p)

    def labels(self, size, scale):
        s = np.asarray(size, dtype=np.float64)
        e = np.asarray(scale, dtype=np.float64)
        cls, _ = size_class_of(s)
        return cls, s / e - 1.0, e

    def sizes(self, cls, r, scale):
        return scale * (1.0 + r)


class FrustumCoding(ExtentCoding):
    name = "frustum"
    needs_bounds = True
    description = ("ref = (x, y: middle of the enclosing box of ALL frustum points; z: centroid of the sampled "
                   "points); points minus ref (float32); centre = ref + center1 + center2; E = (x, y: extents "
                   "of the whole frustum's box; z: extent of the sampled points), each floored at 10% of the "
                   "largest; size = E * (1 + residual[argmax scores])")

    def reference(self, p, bounds):
        lo, hi = bounds[..., 0, :], bounds[..., 1, :]
        ref = p.mean(axis=-2)
        ref[..., :2] = (lo[..., :2] + hi[..., :2]) / 2
        ext = hi - lo
        ext[..., 2] = p[..., 2].max(axis=-1) - p[..., 2].min(axis=-1)
        return ref, _floor_extent(ext)


SIZE_CODINGS: dict[str, SizeCoding] = {c.name: c for c in (PointsCoding(), PaperCoding(), ExtentCoding(),
                                                           FrustumCoding())}


def size_coding(name: str) -> SizeCoding:
    """The coding object of a model's ``size_norm`` name; ValueError naming the known ones."""
    try:
        return SIZE_CODINGS[str(name)]
    except KeyError:
        raise ValueError(f"unknown size coding {name!r} (known: {', '.join(SIZE_CODINGS)})") from None
