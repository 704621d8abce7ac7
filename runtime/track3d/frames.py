"""The data contract shared by every tracker, estimator and the loop: an RGB image is a
(H, W, 3) uint8 array with H, W >= 1; a sensor cloud is (N, 3) and may hold nan / inf (the
frustum drops them, see track3d.frustum); the points handed to a 3D box estimator are (n, 3),
n >= 1, all finite. One check each, one message each."""
from __future__ import annotations

import numpy as np

__all__ = ["check_image", "check_estimator_points"]


def check_image(image, size: tuple[int, int] | None = None) -> np.ndarray:
    """Return `image` as a C-contiguous (H, W, 3) uint8 array, or raise ValueError.

    size: the expected (width, height), e.g. the camera's; a frame of another size would put
    the frustum in the wrong place, so it is refused rather than tracked."""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB with H, W >= 1, got {a.shape} {a.dtype}")
    if size is not None and (a.shape[1], a.shape[0]) != (int(size[0]), int(size[1])):
        raise ValueError(f"image is {a.shape[1]}x{a.shape[0]} but the camera is {int(size[0])}x{int(size[1])}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


def check_estimator_points(points, dtype=np.float32) -> np.ndarray:
    """Return the points of a 3D box estimate as (n, 3) `dtype`, or raise ValueError: an empty
    set, another shape, or a non-finite coordinate would otherwise come back as a nan box."""
    p = np.asarray(points, dtype=dtype)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"estimator points must have shape (n, 3), got {p.shape}")
    if len(p) == 0:
        raise ValueError("a 3D box estimate needs at least one point")
    if not np.isfinite(p).all():
        raise ValueError("estimator points must be finite (the frustum drops nan / inf; see track3d.frustum)")
    return p
