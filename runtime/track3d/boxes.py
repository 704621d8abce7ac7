"""Boxes and overlaps: the ONE implementation of box formulas in the project.

- 2D box: [x, y, w, h] pixels, top-left corner + size (OTB / GOT-10k convention).
- 3D box: axis-aligned [cx, cy, cz, sx, sy, sz] in the left camera frame, metres.
- BEV box: the x-z plane, [cx, cz, sx, sz].
- Size classes: the 14 x/y/z ratio templates of the paper's Table 1.

All functions take single boxes or stacks (N, k) and broadcast like numpy.
Degenerate boxes (zero or negative size, nan) have IoU 0 with everything.
"""
from __future__ import annotations

import numpy as np

from .frames import point_bounds

__all__ = [
    "SIZE_TEMPLATES", "NUM_SIZE_CLASSES",
    "iou_2d", "iou_3d", "iou_bev", "box3d_to_bev", "center_2d", "center_error_2d", "center_error_3d",
    "size_class_of", "encode_size", "decode_size", "box3d_from_points", "clip_box2d", "fit_measured_faces",
    "hold_cut_extent",
]

_T = 1.0 / 3.0
# Table 1 of the paper: columns are categories 0..13, rows the x, y, z ratios.
SIZE_TEMPLATES = np.array([
    [1, 1, 1], [1 / 2, 1, 1], [_T, 1, 1], [2 / 3, 1, 1], [1, 1 / 2, 1], [1, 2 / 3, 1], [1, 1, 1 / 2],
    [1, 1, 2 / 3], [1 / 2, 1 / 2, 1], [2 / 3, 2 / 3, 1], [1 / 2, 1, 1 / 2], [2 / 3, 1, 2 / 3],
    [1, 1 / 2, 1 / 2], [1, 2 / 3, 2 / 3],
], dtype=np.float64)
NUM_SIZE_CLASSES = len(SIZE_TEMPLATES)


def _overlap_1d(a0, a1, b0, b1):
    return np.clip(np.minimum(a1, b1) - np.maximum(a0, b0), 0.0, None)


def _iou_from(inter, va, vb):
    union = va + vb - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where((va > 0) & (vb > 0) & (union > 0), inter / union, 0.0)
    # inter / union of a box with itself can round to 1 + 4e-16 (or below 1 by 1e-14): clamp, so
    # that an IoU never exceeds 1 and never counts above the success threshold 1.0
    return np.clip(np.nan_to_num(iou, nan=0.0), 0.0, 1.0)


def _valid_sizes(*sizes):
    ok = True
    for s in sizes:
        ok = ok & np.isfinite(s) & (s > 0)
    return ok


def iou_2d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of [x, y, w, h] boxes; (..., 4) x (..., 4) -> (...)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ix = _overlap_1d(a[..., 0], a[..., 0] + a[..., 2], b[..., 0], b[..., 0] + b[..., 2])
    iy = _overlap_1d(a[..., 1], a[..., 1] + a[..., 3], b[..., 1], b[..., 1] + b[..., 3])
    va = np.where(_valid_sizes(a[..., 2], a[..., 3]), a[..., 2] * a[..., 3], 0.0)
    vb = np.where(_valid_sizes(b[..., 2], b[..., 3]), b[..., 2] * b[..., 3], 0.0)
    return _iou_from(ix * iy, va, vb)


def _iou_axis_aligned(a: np.ndarray, b: np.ndarray, dims: int) -> np.ndarray:
    inter = 1.0
    va = 1.0
    vb = 1.0
    for k in range(dims):
        ca, sa, cb, sb = a[..., k], a[..., dims + k], b[..., k], b[..., dims + k]
        inter = inter * _overlap_1d(ca - sa / 2, ca + sa / 2, cb - sb / 2, cb + sb / 2)
        va = va * np.where(_valid_sizes(sa), sa, 0.0)
        vb = vb * np.where(_valid_sizes(sb), sb, 0.0)
    return _iou_from(inter, va, vb)


def iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of axis-aligned [cx, cy, cz, sx, sy, sz] boxes; (..., 6) x (..., 6) -> (...)."""
    return _iou_axis_aligned(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), 3)


def box3d_to_bev(box3d: np.ndarray) -> np.ndarray:
    """(..., 6) 3D boxes -> (..., 4) bird's-eye-view boxes [cx, cz, sx, sz] (the x-z plane)."""
    b = np.asarray(box3d, dtype=np.float64)
    return np.stack([b[..., 0], b[..., 2], b[..., 3], b[..., 5]], axis=-1)


def iou_bev(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bird's-eye-view IoU of two 3D boxes (..., 6), in the x-z plane; 0 where either is not a
    box (a non-finite value or a size <= 0 in any axis, y included: a result row with a NaN
    height scored a perfect BEV overlap while its 3D IoU was 0)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ok = _whole_box(a) & _whole_box(b)
    return np.where(ok, _iou_axis_aligned(box3d_to_bev(a), box3d_to_bev(b), 2), 0.0)


def _whole_box(box: np.ndarray) -> np.ndarray:
    """(..., 6) -> (...): every value finite and every size > 0."""
    return np.all(np.isfinite(box), axis=-1) & np.all(box[..., 3:6] > 0, axis=-1)


def center_2d(box2d: np.ndarray) -> np.ndarray:
    """(..., 4) [x, y, w, h] -> (..., 2) centres."""
    b = np.asarray(box2d, dtype=np.float64)
    return b[..., :2] + b[..., 2:4] / 2.0


def center_error_2d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance in pixels between 2D box centres."""
    return np.linalg.norm(center_2d(a) - center_2d(b), axis=-1)


def center_error_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distance in metres between 3D box centres."""
    return np.linalg.norm(np.asarray(a, np.float64)[..., :3] - np.asarray(b, np.float64)[..., :3], axis=-1)


def size_class_of(size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Size class coding of the paper (Table 1, Appendix B).

    size: (..., 3) full extents (metres). The class is the template nearest (Euclidean)
    to size / max(size); the residual is size / max(size) - template[class], i.e. the
    size residual normalised by the largest extent.
    Returns (cls (...,) int64, residual (..., 3) float64).
    """
    s = np.asarray(size, dtype=np.float64)
    scale = s.max(axis=-1, keepdims=True)
    if np.any(~np.isfinite(s)) or np.any(scale <= 0):
        raise ValueError("size_class_of needs finite, positive sizes")
    ratio = s / scale
    d = np.linalg.norm(ratio[..., None, :] - SIZE_TEMPLATES, axis=-1)
    cls = d.argmin(axis=-1)
    return cls.astype(np.int64), ratio - SIZE_TEMPLATES[cls]


encode_size = size_class_of


def decode_size(cls: np.ndarray, residual: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Inverse of the coding: (template[cls] + residual) * scale -> (..., 3) metres.

    scale is the remapping length: at training time max(size); at inference the largest
    extent of the points' enclosing box (paper section IV-B).
    """
    cls = np.asarray(cls, dtype=np.int64)
    return (SIZE_TEMPLATES[cls] + np.asarray(residual, np.float64)) * np.asarray(scale, np.float64)[..., None]


def box3d_from_points(points: np.ndarray) -> np.ndarray:
    """Minimum enclosing axis-aligned box (6,) of (N, 3) points: the paper's 3D baseline.

    Raises ValueError on an empty set (the caller turns that into a 'no points' status).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError("no points to enclose")
    lo, hi = point_bounds(p)
    return np.concatenate([(lo + hi) / 2.0, hi - lo])


def fit_measured_faces(box3d: np.ndarray, bounds: np.ndarray,
                       open_sides: tuple[bool, bool, bool, bool] = (False, False, False, False),
                       pad: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The box (6,) float64 whose faces a depth sensor sees come from the returns and whose hidden
    back face stays the estimate's: x and y extent = the returns' [min, max] (a lone body's
    outline), front face = the nearest return, back face = box3d's. bounds (2, 3) [min; max] of
    the returns. open_sides (x min, y min, x max, y max): sides where the body may go on past
    what was seen (its 2D box at the image border); there the face is the farther of the
    returns' and the estimate's, and so is the front (the nearest part may be out of view).
    pad (x, y): metres per metre of depth added to a measured axis, half on each measured face,
    at the box's middle depth: a depth map's returns are its pixels' centres, so the outline lies
    on average half a pixel beyond the outermost ones (`Track3D(edge_pad=...)` passes one pixel,
    1 / fx and 1 / fy). An axis whose measured extent is under 1 mm, or a front not in front of
    the back face, keeps box3d's; a bound that is not finite changes nothing."""
    b = np.array(box3d, dtype=np.float64).reshape(6)
    lo, hi = (np.asarray(v, dtype=np.float64).reshape(3) for v in bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return b
    elo, ehi = b[:3] - b[3:] / 2.0, b[:3] + b[3:] / 2.0
    front = min(lo[2], elo[2]) if any(open_sides) else lo[2]
    back = ehi[2]
    if front < back:
        b[5] = back - front
        b[2] = front + b[5] / 2.0
    for k in (0, 1):
        if hi[k] - lo[k] < 1e-3:
            continue
        half = 0.5 * float(pad[k]) * max(float(b[2]), 0.0)
        a0 = min(lo[k], elo[k]) if open_sides[k] else lo[k] - half
        a1 = max(hi[k], ehi[k]) if open_sides[2 + k] else hi[k] + half
        b[k], b[3 + k] = (a0 + a1) / 2.0, a1 - a0
    return b


def hold_cut_extent(box3d: np.ndarray, bounds: np.ndarray, open_sides: tuple[bool, bool, bool, bool],
                    whole_box: np.ndarray, below: float, extent: np.ndarray | None = None) -> np.ndarray:
    """The box (6,) float64 of a body cut by the image border, sized from the last view that saw
    it whole: the returns of a cut body span only its visible part, and an estimator shown that
    part sizes the part.

    box3d: the box with its seen faces measured (`fit_measured_faces`); bounds (2, 3) [min; max]
    of the returns; open_sides (x min, y min, x max, y max) as in `fit_measured_faces`;
    whole_box (6,) the box of the last whole view; below: the fraction of the whole extent under
    which a cut axis's returns count as a part. On an axis (x, y) open on one side whose returns
    span less than `below` x its whole extent, the seen face stays where the returns put it and
    the open one lies the whole extent away (the estimate's guess of it is dropped); on an axis
    open on neither side, the extent grows to the whole one if shorter (a cap cut off in x also
    spans less of y): about the box's middle, or, when another axis is such a part, about the
    whole view's middle moved the least to hold the returns (a sliver's middle is not the
    body's). When an axis is such a part, the nearest part of the body may be out of view too:
    the front face is the nearer of the returns' and the whole view's, and the box reaches back
    at least the whole depth from it. An axis open on both sides (a body larger than the view)
    whose returns span less than `below` x its whole extent is such a part too: the whole extent
    about the whole view's middle moved the least to hold the returns. Bounds that are not finite
    change nothing.

    extent: (3,) the body's extent now, when known better than the whole view's (the past views
    carried into this frame: the body has turned since): the extent held; an axis is a part when
    its returns span less than `below` x the larger of the two (the views show at least the
    extent they saw, a side never seen is missing from it)."""
    b = np.array(box3d, dtype=np.float64).reshape(6)
    lo, hi = (np.asarray(v, dtype=np.float64).reshape(3) for v in bounds)
    whole = np.asarray(whole_box, dtype=np.float64).reshape(6)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(np.isfinite(whole))):
        return b
    size = whole[3:] if extent is None else np.asarray(extent, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(size)):
        size = whole[3:]
    test = np.maximum(whole[3:], size)
    opens = [(bool(open_sides[k]), bool(open_sides[2 + k])) for k in (0, 1)]
    # an open axis whose returns are a part of the body's whole extent
    cut = [(o0 or o1) and hi[k] - lo[k] < below * test[k] for k, (o0, o1) in enumerate(opens)]
    part = any(cut)
    for k, (o0, o1) in enumerate(opens):
        if cut[k] and o0 and o1:
            # a body larger than the view: the whole extent about the whole view's middle moved
            # the least to hold the returns (the view's middle is not the body's)
            c = min(max(whole[k], hi[k] - size[k] / 2.0), lo[k] + size[k] / 2.0)
            a0, a1 = c - size[k] / 2.0, c + size[k] / 2.0
        elif cut[k]:
            a0, a1 = (min(lo[k], hi[k] - size[k]), hi[k]) if o0 else (lo[k], max(hi[k], lo[k] + size[k]))
        elif o0 or o1:
            continue
        elif size[k] > b[3 + k]:
            # on a part of the body, the whole view's middle moved the least to hold the returns
            c = min(max(whole[k], hi[k] - size[k] / 2.0), lo[k] + size[k] / 2.0) if part else b[k]
            a0, a1 = c - size[k] / 2.0, c + size[k] / 2.0
        else:
            continue
        b[k], b[3 + k] = (a0 + a1) / 2.0, a1 - a0
    if part:
        front = min(lo[2], whole[2] - size[2] / 2.0)
        back = max(b[2] + b[5] / 2.0, front + size[2])
        b[2], b[5] = (front + back) / 2.0, back - front
    return b


def clip_box2d(box2d: np.ndarray, width: int, height: int) -> np.ndarray:
    """Clip [x, y, w, h] to the image; a box wholly outside gets zero width/height."""
    b = np.asarray(box2d, dtype=np.float64)
    x0 = np.clip(b[..., 0], 0, width)
    y0 = np.clip(b[..., 1], 0, height)
    x1 = np.clip(b[..., 0] + b[..., 2], 0, width)
    y1 = np.clip(b[..., 1] + b[..., 3], 0, height)
    return np.stack([x0, y0, x1 - x0, y1 - y0], axis=-1)
