"""2D-3D tracking fusion (paper section IV-C, eq. for A-hat).

The fused box is a weighted average, component-wise on [x, y, w, h], of the 2D tracker's box
A_2d and A_proj, the image rectangle of the 3D box's centre cross-section (the x-y rectangle
at z = cz, ``Camera.project_box3d_section``): A = w3 * A_proj + (1 - w3) * A_2d, w3 = 0.3.

The other way (``fuse_section``, not in the paper): the 3D box's centre cross-section moved
toward the 2D box's rectangle at the box's centre depth, S = w2 * S_2d + (1 - w2) * S_3d on
[cx, cy, sx, sy] in metres; cz and sz stay the estimator's. For depth whose lateral extent is
noisier than the image's outline (block-matching stereo: foreground fattening, smeared rims).
"""
from __future__ import annotations

import numpy as np

from .camera import Camera

__all__ = ["WEIGHT_3D", "WEIGHT_2D", "fuse", "fuse_section", "box2d_section"]

WEIGHT_3D = 0.3  # lambda_1 of the paper; lambda_2 = 0.7 weighs the 2D tracker
WEIGHT_2D = 0.0  # the paper's 3D box is the estimator's alone


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


def box2d_section(box2d: np.ndarray, camera: Camera, z: float) -> np.ndarray:
    """[cx, cy, sx, sy] (4,) float64 in metres: the rectangle at depth z that projects onto
    box2d [x, y, w, h] (the inverse of ``Camera.project_box3d_section`` at that depth)."""
    x, y, w, h = (float(v) for v in np.asarray(box2d, dtype=np.float64).reshape(4))
    return np.array([(x + w / 2.0 - camera.cx) / camera.fx * z, (y + h / 2.0 - camera.cy) / camera.fy * z,
                     w / camera.fx * z, h / camera.fy * z])


def fuse_section(box3d: np.ndarray, box2d: np.ndarray, camera: Camera, weight_2d: float) -> np.ndarray:
    """The 3D box (6,) float64 with its centre cross-section [cx, cy, sx, sy] moved toward the
    2D box's rectangle at depth cz by `weight_2d` (0: box3d unchanged, 1: the 2D box's);
    a box that is not finite or has cz <= 0 is returned unchanged."""
    if not 0.0 <= float(weight_2d) <= 1.0:
        raise ValueError(f"weight_2d must be in [0, 1], got {weight_2d}")
    b = np.array(box3d, dtype=np.float64).reshape(6)
    if weight_2d == 0.0 or not np.all(np.isfinite(b)) or b[2] <= 0.0:
        return b
    s2 = box2d_section(box2d, camera, b[2])
    if not np.all(np.isfinite(s2)):
        return b
    k = [0, 1, 3, 4]
    b[k] = weight_2d * s2 + (1.0 - weight_2d) * b[k]
    return b
