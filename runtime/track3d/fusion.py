"""2D-3D tracking fusion (paper section IV-C, eq. for A-hat).

The fused box is a weighted average, component-wise on [x, y, w, h], of the 2D tracker's box
A_2d and A_proj, the image rectangle of the 3D box's centre cross-section (the x-y rectangle
at z = cz, ``Camera.project_box3d_section``): A = w3 * A_proj + (1 - w3) * A_2d, w3 = 0.3.
"""
from __future__ import annotations

import numpy as np

from .camera import Camera

__all__ = ["WEIGHT_3D", "fuse"]

WEIGHT_3D = 0.3  # lambda_1 of the paper; lambda_2 = 0.7 weighs the 2D tracker


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
