"""The frame contract shared by every tracker and the loop: an RGB image is a (H, W, 3) uint8
array with H, W >= 1; a point cloud is (N, 3) (see track3d.frustum). One check, one message."""
from __future__ import annotations

import numpy as np

__all__ = ["check_image"]


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
