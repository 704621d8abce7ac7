"""Depth sensors: how a sequence's depth map is measured from the rendered geometry.

The labels (2D and 3D boxes) are always the geometry's; only the stored depth map (and so the
point cloud a tracker sees) depends on the sensor. `dataset.json` and each sequence's
`meta.json` say which sensor made the depth.

    z = measure_depth("tof", frame, camera, rng)     # (H, W) float64 metres, 0 = no return
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SimError

__all__ = ["RenderedFrame", "DEPTH_SENSORS", "measure_depth"]


@dataclass
class RenderedFrame:
    """What the renderer knows of one frame, in the left camera's pixel grid.

    z: (H, W) float64 true depth (z, not range) in metres, 0 = background;
    cos_incidence: (H, W) float32 cosine between the surface normal and the ray to the camera
      (0 where there is no hit); albedo: (H, W) float32 mean albedo of the hit surface (0..1);
    left, right: (H, W, 3) uint8 RGB images as written to disk (right: camera at +baseline)."""

    z: np.ndarray
    cos_incidence: np.ndarray
    albedo: np.ndarray
    left: np.ndarray
    right: np.ndarray


def _ideal(frame: RenderedFrame, camera, rng: np.random.Generator) -> np.ndarray:
    return np.asarray(frame.z, dtype=np.float64)


DEPTH_SENSORS = {"ideal": _ideal}


def measure_depth(sensor: str, frame: RenderedFrame, camera, rng: np.random.Generator) -> np.ndarray:
    """The depth map (H, W) float64 metres (0 = no return) that `sensor` measures of `frame`."""
    f = DEPTH_SENSORS.get(sensor)
    if f is None:
        raise SimError(f"unknown depth sensor {sensor!r} (choose from {', '.join(DEPTH_SENSORS)})")
    return f(frame, camera, rng)
