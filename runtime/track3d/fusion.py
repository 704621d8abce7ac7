"""2D-3D tracking fusion (paper section IV-C, eq. for A-hat).

The fused box is a weighted average, component-wise on [x, y, w, h], of the 2D tracker's box
A_2d and A_proj, the image rectangle of the 3D box's centre cross-section (the x-y rectangle
at z = cz, ``Camera.project_box3d_section``): A = w3 * A_proj + (1 - w3) * A_2d, w3 = 0.3.

The other way (``fuse_section``, not in the paper): the 3D box's centre cross-section moved
toward the 2D box's rectangle at the box's centre depth, S = w2 * S_2d + (1 - w2) * S_3d on
[cx, cy, sx, sy] in metres; cz and sz stay the estimator's. For depth whose lateral extent is
noisier than the image's outline (block-matching stereo: foreground fattening, smeared rims).
The 2D box's sides can each be put at the depth of the body's limb there instead of at cz
(`limb_depths`: the outline is where the rays graze the body, which may lie metres in front of or
behind its centre).
"""
from __future__ import annotations

import numpy as np

from .camera import Camera

__all__ = ["WEIGHT_3D", "WEIGHT_2D", "LIMB_MIN_POINTS", "fuse", "fuse_section", "box2d_section", "limb_depths"]

WEIGHT_3D = 0.3  # lambda_1 of the paper; lambda_2 = 0.7 weighs the 2D tracker
WEIGHT_2D = 0.0  # the paper's 3D box is the estimator's alone
LIMB_MIN_POINTS = 5


def fuse(box2d: np.ndarray, box3d: np.ndarray, camera: Camera, weight_3d: float = WEIGHT_3D) -> np.ndarray:
    """Fused 2D box (4,) float64 from a 2D box (4,) and a 3D box (6,).

    When A_proj is not finite (a 3D box behind the camera, or a nan box) box2d is returned
    unchanged: there is nothing to fuse with.
    """
    if not 0.0 <= float(weight_3d) <= 1.0:
        raise ValueError(f"weight_3d must be in [0, 1], got {weight_3d}")
    a2d = np.asarray(box2d, dtype=np.float64).reshape(4)
    proj = camera.project_box3d_section(np.asarray(box3d, dtype=np.float64).reshape(6))
    if not np.all(np.isfinite(proj)):
        return a2d.copy()
    return weight_3d * proj + (1.0 - weight_3d) * a2d


def box2d_section(box2d: np.ndarray, camera: Camera, z) -> np.ndarray:
    """[cx, cy, sx, sy] (4,) float64 in metres: the rectangle that projects onto box2d
    [x, y, w, h], each side at its own depth. z: one depth (the inverse of
    ``Camera.project_box3d_section`` at that depth), or (4,) depths of the left, top, right and
    bottom sides (`limb_depths`)."""
    x, y, w, h = (float(v) for v in np.asarray(box2d, dtype=np.float64).reshape(4))
    zl, zt, zr, zb = np.broadcast_to(np.asarray(z, dtype=np.float64), (4,))
    left, right = (x - camera.cx) / camera.fx * zl, (x + w - camera.cx) / camera.fx * zr
    top, bottom = (y - camera.cy) / camera.fy * zt, (y + h - camera.cy) / camera.fy * zb
    return np.array([(left + right) / 2.0, (top + bottom) / 2.0, right - left, bottom - top])


def limb_depths(points: np.ndarray, box2d: np.ndarray, camera: Camera, band: tuple[float, float],
                quantile: float, min_points: int = LIMB_MIN_POINTS) -> np.ndarray:
    """(4,) float64: the depth of the body's limb at the left, top, right and bottom side of
    box2d [x, y, w, h], from the returns `points` (N, 3) whose pixels lie within the side's band
    (max(band[0] px, band[1] of the box's size) inward of the side): their `quantile` (0..1) of
    depth, the limb being the farthest surface the camera sees near the outline; nan for a side
    with fewer than `min_points` returns there."""
    out = np.full(4, np.nan)
    p = np.asarray(points).reshape(-1, 3)
    z = p[:, 2]
    front = z > 0.0
    if np.count_nonzero(front) < min_points:
        return out
    x, y, w, h = (float(v) for v in np.asarray(box2d, dtype=np.float64).reshape(4))
    bx, by = max(band[0], band[1] * w), max(band[0], band[1] * h)
    # a pixel column u bounds X / z: u < c  <=>  X < z (c - cx) / fx for z > 0 (no division per point)
    ax0, ax1 = (x + bx - camera.cx) / camera.fx, (x + w - bx - camera.cx) / camera.fx
    ay0, ay1 = (y + by - camera.cy) / camera.fy, (y + h - by - camera.cy) / camera.fy
    for k, sel in enumerate((p[:, 0] < ax0 * z, p[:, 1] < ay0 * z, p[:, 0] > ax1 * z, p[:, 1] > ay1 * z)):
        sel &= front
        if np.count_nonzero(sel) >= min_points:
            out[k] = float(np.quantile(z[sel].astype(np.float64), quantile))
    return out


def fuse_section(box3d: np.ndarray, box2d: np.ndarray, camera: Camera, weight_2d: float,
                 limbs: np.ndarray | None = None) -> np.ndarray:
    """The 3D box (6,) float64 with its centre cross-section [cx, cy, sx, sy] moved toward the
    2D box's rectangle by `weight_2d` (0: box3d unchanged, 1: the 2D box's), the rectangle's sides
    at depth cz or at `limbs` (4,) (`limb_depths`; a nan side at cz; an image axis whose two sides
    cross at their limbs' depths at cz); a box that is not finite or has cz <= 0 is returned
    unchanged."""
    if not 0.0 <= float(weight_2d) <= 1.0:
        raise ValueError(f"weight_2d must be in [0, 1], got {weight_2d}")
    b = np.array(box3d, dtype=np.float64).reshape(6)
    if weight_2d == 0.0 or not np.all(np.isfinite(b)) or b[2] <= 0.0:
        return b
    if limbs is None:
        z = np.full(4, b[2])
    else:   # a limb lies on the body: within the box's depth
        z = np.where(np.isfinite(limbs), np.clip(limbs, b[2] - b[5] / 2.0, b[2] + b[5] / 2.0), b[2])
    s2 = box2d_section(box2d, camera, z)
    # Two sides on one side of the optical axis, the nearer one farther out, cross at their
    # limbs' depths (a box in an image corner, limbs metres apart): no body has a negative
    # extent, so those limbs are not both its outline; that axis goes back to cz.
    crossed = ~(s2[2:] > 0.0)
    if crossed.any():
        s2 = np.where(np.tile(crossed, 2), box2d_section(box2d, camera, b[2]), s2)
    if not np.all(np.isfinite(s2)):
        return b
    k = [0, 1, 3, 4]
    b[k] = weight_2d * s2 + (1.0 - weight_2d) * b[k]
    return b
