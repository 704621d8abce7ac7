"""The body's dark side in the image, from the sun's direction.

A camera, and stereo depth matched from its images, sees the lit part of the body only: at a
phase angle alpha (sun - body - observer) a sphere of radius r shows r (1 + cos alpha) of its
2 r across the image toward the sun, the rest lying dark beyond the terminator. A spacecraft
knows where the sun is (sun sensor, ephemeris), so the part of the outline it cannot see can be
placed: on the side away from the sun. `dark_side_box` extends a lit outline there by a share
of the sphere's missing part (`k`, chosen by measurement: real bodies are not spheres, and the
terminator of a rough one is not sharp); `reach_dark_side` pushes a box's sides away from the
sun out to at least that extended outline, never pulling one in.

Directions are in the camera frame of `track3d.camera` (x right, y down, z forward); the sun's
is a vector toward the sun (any length > 0).
"""
from __future__ import annotations

import numpy as np

from .camera import Camera

__all__ = ["check_sun", "dark_share", "dark_side_box", "phase_deg", "reach_dark_side", "DARK_SHARE_CAP"]

# The largest extension, as a share of the lit outline's extent toward the sun: past ~110 degrees
# of phase the sphere's ratio (1 - cos a) / (1 + cos a) runs away (a thin crescent, 14x at 150
# degrees), and a crescent's outline says little of the body behind it.
DARK_SHARE_CAP = 1.0


def check_sun(direction) -> np.ndarray | None:
    """`direction` as a unit (3,) float64 vector, or None for None; ValueError for anything that
    is not three finite numbers of non-zero length."""
    if direction is None:
        return None
    try:
        d = np.asarray(direction, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ValueError(f"sun direction must be 3 numbers (camera frame, toward the sun), got {direction!r:.80}") from None
    if not np.all(np.isfinite(d)):
        raise ValueError(f"sun direction must be 3 finite numbers of non-zero length, got {d.tolist()}")
    with np.errstate(over="ignore"):
        n = float(np.linalg.norm(d))
    if np.isfinite(n) and n > 1e-12:
        return d / n
    # scaled first where the norm over- or underflows: [1e308] * 3 had come out [0, 0, 0], which
    # the state then refused to restore; [1e-200, 0, 0] is a direction too
    big = float(np.max(np.abs(d)))
    if not big > 0.0:
        raise ValueError(f"sun direction must be 3 finite numbers of non-zero length, got {d.tolist()}")
    d = d / big
    return d / float(np.linalg.norm(d))


def _centre_ray(box2d: np.ndarray, camera: Camera) -> np.ndarray:
    """The unit (3,) ray through the centre of the box [x, y, w, h]."""
    x, y, w, h = (float(v) for v in box2d)
    ray = np.array([(x + w / 2.0 - camera.cx) / camera.fx, (y + h / 2.0 - camera.cy) / camera.fy, 1.0])
    return ray / np.linalg.norm(ray)


def phase_deg(box2d: np.ndarray, sun: np.ndarray, camera: Camera) -> float:
    """The phase angle (sun - body - observer, degrees in [0, 180]) at the centre ray of the box
    [x, y, w, h]: 0 with the sun behind the camera (the body fully lit), above 90 a crescent."""
    c = float(-(np.asarray(sun, dtype=np.float64) @ _centre_ray(box2d, camera)))   # the observer back along the ray
    return float(np.degrees(np.arccos(min(max(c, -1.0), 1.0))))


def _sun_at(box2d: np.ndarray, sun: np.ndarray, camera: Camera) -> tuple[float, np.ndarray] | None:
    """(cos a, u) at the box's centre ray: a the phase angle, u (2,) the unit image direction
    toward the sun; None when the sun lies along that ray (no side)."""
    ray = _centre_ray(box2d, camera)
    across = sun - float(sun @ ray) * ray      # the sun's direction across the line of sight
    u = np.array([across[0] * camera.fx, across[1] * camera.fy])
    n = float(np.linalg.norm(u))
    if n < 1e-9:
        return None
    return float(-sun @ ray), u / n            # the observer lies back along the ray


def dark_share(box2d: np.ndarray, sun: np.ndarray, camera: Camera, k: float,
               cap: float = DARK_SHARE_CAP) -> tuple[float, np.ndarray] | None:
    """(share, u): the dark part's extent as a share of the lit extent toward the sun, ``min(cap,
    k (1 - cos a) / (1 + cos a))`` with a the phase angle at the box's centre ray, and u (2,) the
    unit image direction toward the sun there; None when the sun lies along that ray (no side)."""
    got = _sun_at(box2d, sun, camera)
    if got is None:
        return None
    cos_a, u = got
    return min(float(cap), k * (1.0 - cos_a) / max(1.0 + cos_a, 1e-9)), u


def dark_side_box(lit: np.ndarray, sun: np.ndarray, camera: Camera, k: float,
                  cap: float = DARK_SHARE_CAP) -> np.ndarray:
    """The lit outline `lit` [x, y, w, h] extended away from the sun (the dark side) by the share
    `dark_share` of its width (x) and height (y), each weighted by how much the sun's image
    direction lies along that axis; a new float64 array, `lit` unchanged when there is no side."""
    b = np.array(lit, dtype=np.float64).reshape(4)
    got = dark_share(b, sun, camera, k, cap) if k > 0.0 and np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0 else None
    if got is None:
        return b
    share, u = got
    for a in (0, 1):
        grow = share * b[a + 2] * abs(float(u[a]))
        if u[a] > 0.0:          # the sun toward +axis: the dark side is on the low side
            b[a] -= grow
        b[a + 2] += grow
    return b


def reach_dark_side(box2d: np.ndarray, dark: np.ndarray, sun: np.ndarray, camera: Camera) -> np.ndarray:
    """`box2d` [x, y, w, h] with each side away from the sun pushed out to at least `dark`'s
    (the extended outline of `dark_side_box`), the other sides kept; a new float64 array."""
    b = np.array(box2d, dtype=np.float64).reshape(4)
    d = np.asarray(dark, dtype=np.float64).reshape(4)
    got = _sun_at(b, sun, camera) if np.all(np.isfinite(b)) and np.all(np.isfinite(d)) else None
    if got is None:
        return b
    _, u = got
    for a in (0, 1):
        if u[a] > 0.0 and d[a] < b[a]:                       # dark side low
            b[a + 2] += b[a] - d[a]
            b[a] = d[a]
        elif u[a] < 0.0 and d[a] + d[a + 2] > b[a] + b[a + 2]:   # dark side high
            b[a + 2] = d[a] + d[a + 2] - b[a]
    return b
