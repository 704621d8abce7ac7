"""Returns that are no part of the body: lone false alarms of a depth sensor in the frustum.

A photon-counting flash LiDAR or a ToF camera reports now and then a return where there is no
surface (a dark count, a solar photon, a dust grain), at any range the sensor gates. One such
return in front of the body had set the measured front face, and with it the box: ideal depth
with one false alarm in 100,000 pixels (three a frame over a 640 x 480 image) took the ideal
calibration set's AO_3d from 0.904 to 0.456 (docs/runtime.md, "False alarms").

The body's returns are neighbours of one another, in the image and in depth: one run of depths
with no gap wider than a few centimetres between neighbours in depth order, or a few runs where
one part of the body hides another, each a patch of neighbouring pixels. A false alarm has no
neighbour: on the sky it has no other return near it in the image; over the body it has none
near it in depth. `drop_stray` drops
- each return with no other within the 3 x 3 cells of STRAY_CELL_PX pixels around its own (the
  sky's false alarms; a flash LiDAR's returns lie ~5 px apart in a 640 x 480 image), unless most
  of the returns are lone and at least SPARSE_MIN (a sensor grid coarser than the cells), then
- splitting the rest at every gap wider than `gap_m` in depth, besides the largest run each run
  of fewer than `min_count` returns, and each run of at most `max_check` returns most of which
  have no other return of their run in the 3 x 3 cells of `near_px` / 2 pixels around their own
  (false alarms over the body).
"""
from __future__ import annotations

import numpy as np

from .frames import point_bounds, select_points
from .frustum import lone_scan

__all__ = ["STRAY_GAP_M", "STRAY_MIN_COUNT", "STRAY_NEAR_PX", "STRAY_MAX_CHECK", "STRAY_CELL_PX", "SPARSE_MIN",
           "drop_stray"]

STRAY_GAP_M = 0.5
STRAY_MIN_COUNT = 3
STRAY_NEAR_PX = 8.0
STRAY_MAX_CHECK = 256   # a run this large is no handful of false alarms (and the check is quadratic)
STRAY_CELL_PX = 4.0
# At least this many lone returns, half of the frustum's or more, are a sparse sensor grid, kept
# whole: false alarms come a few at a time (1e-4 a pixel: about one in a 100 x 100 px frustum).
SPARSE_MIN = 16


def _bounds(kept: np.ndarray, dtype) -> np.ndarray:
    """(2, 3) [min; max] of the points kept (n >= 1), column by column (frames.point_bounds: a
    (n, 3) min(axis=0) had cost 1-4 ms on a large frustum, the loop's slowest frames)."""
    return np.stack(point_bounds(kept)).astype(dtype, copy=False)


def drop_stray(pts: np.ndarray, bounds: np.ndarray, M: np.ndarray, gap_m: float = STRAY_GAP_M,
               min_count: int = STRAY_MIN_COUNT, near_px: float = STRAY_NEAR_PX,
               max_check: int = STRAY_MAX_CHECK, cell_px: float = STRAY_CELL_PX) -> tuple[np.ndarray, np.ndarray]:
    """(points (n, 3) float32 in the camera frame of M (3, 4), their bounds (2, 3) [min; max])
    without the stray returns (the module's rule). The arrays come back as they were (the same
    objects) when nothing is dropped; with nothing kept, the bounds are an empty frustum's
    ([inf; -inf], as track3d.frustum gives them)."""
    n = len(pts)
    if n < 2:
        return pts, bounds
    lone, one_run = lone_scan(pts, M, cell_px, gap_m / 2.0)
    lonely = int(np.count_nonzero(lone))
    if lonely >= SPARSE_MIN and 2 * lonely > n:
        # most returns lone, and many: a sensor's grid coarser than the cells (a 128 x 128 flash
        # LiDAR on a 1280 x 960 image lies 10 px apart), not false alarms, which are rare
        lone, one_run = np.zeros(n, bool), False
    keep = ~lone
    if not keep.any():   # nothing but a few lone returns: no body there (an empty frustum, as the loop judges it)
        return pts[:0], np.array([[np.inf] * 3, [-np.inf] * 3], dtype=bounds.dtype)
    if one_run:   # no two of the rest more than gap_m apart in depth: one run, nothing more to drop
        if not lone.any():
            return pts, bounds
        kept = select_points(pts, keep)
        return kept, _bounds(kept, bounds.dtype)
    idx = np.flatnonzero(keep)                 # the returns left, into pts
    zk = pts[idx, 2]
    zs = np.sort(zk)
    cuts = np.flatnonzero(np.diff(zs) > gap_m)
    if len(cuts):
        counts = np.diff(np.concatenate([[0], cuts + 1, [len(zs)]]))
        small = counts <= max_check
        small[int(np.argmax(counts))] = False  # the largest run is the body
        run = np.searchsorted(zs[cuts + 1], zk, side="right")   # each return's run
        cand = np.flatnonzero(small[run])      # the returns of the small runs: few
        cr = run[cand]
        for r in np.unique(cr):
            members = idx[cand[cr == r]]
            if len(members) >= min_count:
                # scattered (false alarms) or a patch (a part of the body seen apart): most of the
                # run's returns without another of the run in the 3 x 3 cells around their own
                alone = lone_scan(pts[members], M, near_px / 2.0, gap_m / 2.0)[0]
                if 2 * int(np.count_nonzero(alone)) <= len(members):
                    continue
            keep[members] = False
    if keep.all():
        return pts, bounds
    kept = select_points(pts, keep)
    return kept, _bounds(kept, bounds.dtype)
