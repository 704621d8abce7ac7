"""Boxes for a body that reaches past the depth sensor's range.

A range-limited depth sensor (an AMCW time-of-flight camera: no return beyond its unambiguous
range, 30 m for the simulator's `tof`) sees only the near cap of a body that reaches past that
range. A3BoxNet, shown the cap, answers with a box the size of the cap (oracle 2D boxes, held-out
ToF sequences at 30-35 m: IoU_3d 0.33 against 0.76-0.79 nearer). The camera still sees the
whole body, so when the returns stop at the range and cover less of the body than the image
does, the box is built from what is measured: the front face (the nearest return), the 2D box's
extent at the box's centre depth across the line of sight, and along it the mean of the two
times a depth-to-width ratio: the hidden depth is not measured, so the ratio is the geometric
mean of 1 and that of the body's last whole view's box (off the image border, returns within
the range; `cut_ratio`; 1 for a body never seen so). When the returns reach the range but
cover the outline (only the rim near the limb is past it), the estimator's box stands, its back
face pushed back to the view box's when that lies farther, the view box as deep for its width
as the body's last whole view's box: the estimator, shown a cloud that stops at the range, guesses a body
as shallow as the cloud.

    cut = is_range_cut(bounds, box2d, camera, range_m)   # bool, from the frustum's [min; max]
    box = box_from_view(box2d, camera, front_z, cut_ratio(last_ratio))   # (6,) [cx, cy, cz, sx, sy, sz]
    box = deepen_to_view(box, box2d, camera, front_z)     # reaches_range but not cut
    box = carry_box(last_box, last_box2d, box2d, camera)  # no return at all: past the range
    box = box_at_range(box2d, camera, range_m)            # no return from the first frame on

All use only the frustum pass's bounds or boxes: no pass over the points. When a body whose
returns had reached the range gives none (wholly past it; the 2D tracker still has it, clear of
the image border), its last box is carried by the image: across the line of sight with the 2D
box's centre, along it by the 2D box's change of scale, damped (`carry_box`). At the image
border the 2D box spans only the part in view: there the box follows the side of the 2D box
that is not at the border, at the same depth (and the next clear view is carried from the last
clear one again). A body that
gives no return from the first frame on (the caller's 2D box on it) is past the range from the
start: boxed from the image with its front face at the range, the nearest it can be
(`box_at_range`), then carried the same way.
"""
from __future__ import annotations

import numpy as np

from .camera import Camera
from .fusion import box2d_section

__all__ = ["reaches_range", "is_range_cut", "view_depth", "box_from_view", "box_at_range", "deepen_to_view", "lateral_coverage",
           "cut_ratio", "CUT_RATIO_WEIGHT", "RANGE_REACH",
           "MIN_COVERAGE", "CAP_FUSION_COVERAGE", "DEPTH_RATIO", "MAX_DEPTH_RATIO", "carry_box", "CARRY_DEPTH_EXPONENT"]

# The returns reach the range when the farthest frustum point lies within this fraction of the
# range (measured along the 2D box's centre ray): the simulator's ToF noise at 30 m is ~2 cm,
# the rim of a body cut at the range is spread over the box's rays.
RANGE_REACH = 0.02
# ... and the cut shows in the image when the returns span less than this fraction of the 2D
# box's width or height at the front face. Chosen on held-out ToF calibration sequences
# (data/engine-calib-tof, 12 x 60 frames, oracle 2D boxes, one pass: AO_3d 0.661 without the
# rule, 0.714 at 0.8, 0.718 at 0.9; another seed, data/engine-calib-tof5: 0.683, 0.752, 0.758).
MIN_COVERAGE = 0.9
# Below this coverage the cap says nothing of the body's extent in the image: fused into the 2D
# box (the loop's 2D fusion uses the estimator's box of the cap) it drew the box onto the cap
# frame after frame (a body 2-4 m past the range: IoU_2d 0.93 -> 0.55 in 20 frames). Chosen on
# ToF calibration sets (EdgeTrack one pass, AO_3d; the seed 3 / seed 9 sets and the same with
# the returns beyond 24 m and 27 m removed, range set to match) at 0 / 0.5 / 0.6 / 0.7 / 0.8:
# 0.749 / 0.748 / 0.748 / 0.746 / 0.743 and 0.745 (all) on the 30 m sets, mean of the four short
# ones 0.484 / 0.486 / 0.487 / 0.488 / 0.489 (AO_2d up on every set): the largest that costs the
# 30 m sets no more than 0.001.
CAP_FUSION_COVERAGE = 0.6
# size z / mean(size x, size y) of a body boxed from the image: no rule of the two lateral extents
# did better on held-out shapes by more than 0.001 (benchmarks/bench_depth_prior.py: the training world's bodies
# 0.790 with the mean, 0.802 with the best power law fitted on them; held-out generators 0.841 /
# 0.837; the simulator's attitudes).
DEPTH_RATIO = 1.0
# A body cut by the range is boxed from the image at the depth-to-width ratio
# DEPTH_RATIO ** (1 - w) x own ** w, `own` that of its last whole view's box (off the image
# border, returns within the range; `cut_ratio`): a flat body is boxed flatter than 1, a long one
# deeper, neither trusted all the way (that box was itself a guess of the hidden depth). Chosen on
# the ToF calibration sets of seeds 3, 9 and 1203 (12 + 12 x 60 frames each; oracle 2D boxes and
# EdgeTrack, one pass, both splits: twelve AO_3d) at w = 0 / 0.5 / 1: mean 0.7869 / 0.7892 /
# 0.7893; at 0.5 no row down by more than 0.0007, at 1 three (seed 9 held-out shapes EdgeTrack
# 0.8089 -> 0.8031: one body 0.06 lower). Capping the ratio at 1 lost all of the gain (seeds 3 / 9:
# 0.7875 against 0.7888 at w = 0); taking `own` from views cut by the image border too cost a
# seed-1203 held-out body 0.033 at w = 0.5. Before the past views, w = 1 had read 0.7582 against
# 0.7579 (held-out ToF seed 5).
CUT_RATIO_WEIGHT = 0.5
# A carried box's depth goes as (s_last / s) ** CARRY_DEPTH_EXPONENT, s the 2D box's sqrt(w h):
# 1 would be a rigid body's range from its apparent size, but a tumbling body's outline changes
# with its attitude too. Chosen on ToF calibration sets (EdgeTrack one pass, AO_3d; seeds 3 / 9 at
# the simulator's 30 m range, then the same with returns beyond 24 m / 27 m removed), box held /
# carried at exponent 0 / 0.5 / 1: 30 m 0.748 / 0.750 / 0.750 / 0.747 and 0.745 / 0.768 / 0.771 /
# 0.766; 24 m 0.450 / 0.456 / 0.463 / 0.465 and 0.342 / 0.348 / 0.363 / 0.386; 27 m 0.570 / 0.573 /
# 0.574 / 0.574 and 0.584 / 0.590 / 0.628 / 0.615.
CARRY_DEPTH_EXPONENT = 0.5
# The largest depth-to-width ratio a body's own earlier box lends deepen_to_view (one box of a
# body seen edge-on must not make the next ones many times deeper than wide).
MAX_DEPTH_RATIO = 1.9


def lateral_coverage(bounds: np.ndarray, box2d: np.ndarray, camera: Camera) -> float:
    """The smaller of (returns' x extent / 2D box width) and (y extent / height), both at the
    nearest return's depth. bounds (2, 3) [min; max] of the frustum points; box2d (4,) [x, y, w, h]."""
    lo, hi = np.asarray(bounds, np.float64)
    z = max(float(lo[2]), 1e-6)
    w, h = float(box2d[2]), float(box2d[3])
    return min((hi[0] - lo[0]) / (w * z / camera.fx), (hi[1] - lo[1]) / (h * z / camera.fy))


def reaches_range(bounds: np.ndarray, box2d: np.ndarray, camera: Camera, range_m: float | None,
                  reach: float = RANGE_REACH) -> bool:
    """True when the frustum's farthest return lies at the sensor's range (`range_m`, metres,
    along the 2D box's centre ray; within the fraction `reach`); None: an unlimited sensor."""
    if range_m is None:
        return False
    return float(np.asarray(bounds)[1, 2]) >= _z_at_range(box2d, camera, range_m) * (1.0 - reach)


def _z_at_range(box2d: np.ndarray, camera: Camera, range_m: float) -> float:
    """The depth z at which the 2D box's centre ray lies `range_m` metres from the camera."""
    cx, cy = box2d_section(box2d, camera, 1.0)[:2]          # the centre ray at z = 1
    return float(range_m) / float(np.sqrt(cx * cx + cy * cy + 1.0))


def is_range_cut(bounds: np.ndarray, box2d: np.ndarray, camera: Camera, range_m: float | None,
                 reach: float = RANGE_REACH, min_coverage: float = MIN_COVERAGE) -> bool:
    """True when the frustum's returns stop at the sensor's range (`range_m`, metres; None: an
    unlimited sensor, never cut) and cover less than `min_coverage` of the 2D box."""
    return (reaches_range(bounds, box2d, camera, range_m, reach)
            and lateral_coverage(bounds, box2d, camera) < min_coverage)


def view_depth(size_x, size_y, ratio: float = DEPTH_RATIO):
    """The depth extent guessed for a body seen only in the image: `ratio` x the mean of its two
    lateral extents (any unit; scalars or arrays). benchmarks/bench_depth_prior.py scores it
    against other rules of the two extents on the training world's bodies."""
    return ratio * (size_x + size_y) / 2.0


def cut_ratio(own: float, weight: float = CUT_RATIO_WEIGHT) -> float:
    """The depth-to-width ratio of a body boxed from the image because its returns stop at the
    range: DEPTH_RATIO ** (1 - weight) * own ** weight, `own` the ratio of the body's last whole
    view's box (off the image border, returns within the range); DEPTH_RATIO when there was none
    (`own` NaN, not finite or <= 0)."""
    own = float(own)
    if not (np.isfinite(own) and own > 0.0):
        return DEPTH_RATIO
    return float(DEPTH_RATIO ** (1.0 - weight) * own ** weight)


def box_from_view(box2d: np.ndarray, camera: Camera, front_z: float,
                  ratio: float = DEPTH_RATIO) -> np.ndarray | None:
    """The box (6,) float64 whose front face is at depth `front_z`, whose cross-section at its
    centre depth projects onto `box2d`, and whose size z is `view_depth` of sizes x and y;
    None when no such box exists (a 2D box so large that the depth would be negative)."""
    x, y, w, h = (float(v) for v in box2d)
    a = view_depth(w / camera.fx, h / camera.fy, ratio)    # size z per metre of centre depth
    if not (front_z > 0.0 and 0.0 <= a < 2.0):
        return None
    zc = front_z / (1.0 - a / 2.0)
    cx, cy, sx, sy = box2d_section(box2d, camera, zc)
    return np.array([cx, cy, zc, sx, sy, a * zc])


def box_at_range(box2d: np.ndarray, camera: Camera, range_m: float,
                 ratio: float = DEPTH_RATIO) -> np.ndarray | None:
    """``box_from_view`` with the front face at the range `range_m` (metres, along the 2D box's
    centre ray): the box of a body the camera sees and the depth sensor does not, as near as it can
    be (no return in its 2D box: past the range). None where box_from_view has none."""
    return box_from_view(box2d, camera, _z_at_range(box2d, camera, range_m), ratio)


def deepen_to_view(box: np.ndarray, box2d: np.ndarray, camera: Camera, front_z: float,
                   ratio: float = DEPTH_RATIO) -> np.ndarray:
    """`box` (6,) with its back face moved back to that of ``box_from_view(box2d, camera,
    front_z, ratio)`` when the latter lies farther (its front face, x and y kept); a new
    float64 array. For a body whose returns reach the range while covering its outline,
    the loop passes the ratio of the body's last box from returns within the range (held-out
    ToF calibration sequences, one pass, AO_3d: oracle 2D boxes 0.7422 -> 0.7446 seed 3, 0.7297
    -> 0.7385 seed 9; EdgeTrack 0.7281 -> 0.7316, 0.7192 -> 0.7271; at ratio 1 always: 0.7439,
    0.7362, 0.7297, 0.7252). Boxing such bodies from the image alone was worse (seed 3: oracle
    0.7396, EdgeTrack 0.7159)."""
    out = np.array(box, dtype=np.float64)
    view = box_from_view(box2d, camera, front_z, ratio)
    if view is None:
        return out
    front, back = out[2] - out[5] / 2.0, view[2] + view[5] / 2.0
    if back > out[2] + out[5] / 2.0:
        out[5] = back - front
        out[2] = front + out[5] / 2.0
    return out


def _carry_ref(box2d: np.ndarray, low: bool, high: bool, k: int) -> float:
    """The coordinate along axis k (0: x, 1: y) of the 2D box [x, y, w, h] that follows the body:
    its centre, or the side not at the image border (`low` / `high`: that side is at it); nan when
    both are."""
    if low and high:
        return float("nan")
    if low:
        return float(box2d[k] + box2d[k + 2])
    if high:
        return float(box2d[k])
    return float(box2d[k] + box2d[k + 2] / 2.0)


def carry_box(box3d: np.ndarray, last_box2d: np.ndarray, box2d: np.ndarray, camera: Camera,
              exponent: float = CARRY_DEPTH_EXPONENT,
              last_sides: tuple[bool, bool, bool, bool] | None = None,
              sides: tuple[bool, bool, bool, bool] | None = None,
              last_whole: tuple[float, float] | None = None) -> np.ndarray:
    """`box3d` (6,), the 3D box that went with the 2D box `last_box2d` (4,) [x, y, w, h], moved
    to go with `box2d` (4,): its centre depth scaled by (s_last / s) ** exponent (s = sqrt(w h)
    of each 2D box), its centre kept on the same offset from the 2D box's centre ray, its size
    kept; a new float64 array. `box3d` unchanged (a copy) when a box is not finite or of no size.

    `last_sides` / `sides`: which sides (left, top, right, bottom) of `last_box2d` / `box2d` lie at
    the image border (None: none). A box at the border spans the part of the body in view, so when
    either does, the box moves across the line of sight with the 2D boxes' side not at the border
    (per axis; with their centres where neither side is, not at all where both are) and keeps its
    depth: the size of a cut box says nothing of the range. `last_whole`: (area px^2, centre depth m)
    of the body's last 2D box clear of the border and its 3D box; with `last_box2d` at the border
    and `box2d` clear, the depth then scales, along the moved centre's ray, as from a clear box of
    the size the body would have had at `box3d`'s depth (sqrt(area) x that depth / `box3d`'s), or of
    `last_box2d`'s own size where that is larger (the part in view is at most the body; a 2D tracker
    that keeps its box's size at the border, as SiamFC does, had the body's)."""
    b = np.array(box3d, dtype=np.float64).reshape(6)
    p, q = np.asarray(last_box2d, np.float64).reshape(4), np.asarray(box2d, np.float64).reshape(4)
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(p)) and np.all(np.isfinite(q))
            and b[2] > 0.0 and min(p[2], p[3], q[2], q[3]) > 0.0):
        return b
    ls = (False,) * 4 if last_sides is None else tuple(bool(v) for v in last_sides)
    cs = (False,) * 4 if sides is None else tuple(bool(v) for v in sides)
    if not (any(ls) or any(cs)):   # both clear: the centre rays
        z = b[2] * float(np.sqrt((p[2] * p[3]) / (q[2] * q[3]))) ** exponent
        ray_p, ray_q = box2d_section(p, camera, 1.0)[:2], box2d_section(q, camera, 1.0)[:2]
        b[:2] = (b[:2] / b[2] - ray_p + ray_q) * z
        b[2] = z
        return b
    shift = np.zeros(2)
    for k, fk in ((0, camera.fx), (1, camera.fy)):
        lo, hi = ls[k] or cs[k], ls[k + 2] or cs[k + 2]
        d = _carry_ref(q, lo, hi, k) - _carry_ref(p, lo, hi, k)
        shift[k] = d / fk if np.isfinite(d) else 0.0
    b[:2] = b[:2] + shift * b[2]
    if any(ls) and not any(cs) and last_whole is not None:
        area, z = (float(v) for v in last_whole)
        if np.isfinite(area) and np.isfinite(z) and area > 0.0 and z > 0.0:
            whole = max(np.sqrt(area) * z / b[2], float(np.sqrt(p[2] * p[3])))   # the body's 2D size there
            b[:3] = b[:3] * (whole / float(np.sqrt(q[2] * q[3]))) ** exponent
    return b
