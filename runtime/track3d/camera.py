"""Pinhole camera of the dataset: the ONE implementation of the camera formulas.

Frame: the left camera, OpenCV style (x right, y down, z forward, metres).
Pixel coordinates are continuous: pixel (i, j) covers u in [i, i+1), v in [j, j+1),
so its centre is (i + 0.5, j + 0.5). Intrinsics follow the paper's eq. (1):
fx = W / (2 tan(ax/2)), fy = H / (2 tan(ay/2)), cx = W/2, cy = H/2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["Camera"]


@dataclass(frozen=True)
class Camera:
    """Two identical pinhole cameras; the right one sits at x = +baseline_m."""

    width: int
    height: int
    fov_x_deg: float
    fov_y_deg: float
    baseline_m: float = 0.4

    def __post_init__(self) -> None:
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"camera resolution must be positive, got {self.width}x{self.height}")
        for name in ("fov_x_deg", "fov_y_deg"):
            v = float(getattr(self, name))
            if not (0.0 < v < 180.0) or not math.isfinite(v):
                raise ValueError(f"camera {name} must be in (0, 180) degrees, got {v}")

    @classmethod
    def from_fov(cls, width: int, height: int, fov_x_deg: float, baseline_m: float = 0.4) -> "Camera":
        """Square pixels: the vertical perspective angle follows from the horizontal one."""
        fy_half = math.atan(height / width * math.tan(math.radians(fov_x_deg) / 2.0))
        return cls(int(width), int(height), float(fov_x_deg), math.degrees(2.0 * fy_half), baseline_m)

    # --- intrinsics (paper eq. 1) ---
    @property
    def fx(self) -> float:
        return self.width / (2.0 * math.tan(math.radians(self.fov_x_deg) / 2.0))

    @property
    def fy(self) -> float:
        return self.height / (2.0 * math.tan(math.radians(self.fov_y_deg) / 2.0))

    @property
    def cx(self) -> float:
        return self.width / 2.0

    @property
    def cy(self) -> float:
        return self.height / 2.0

    @cached_property
    def K(self) -> np.ndarray:
        """(3, 3) float64 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @cached_property
    def M(self) -> np.ndarray:
        """(3, 4) float64 camera matrix of the left camera, K [I | 0] (paper Appendix A)."""
        return np.hstack([self.K, np.zeros((3, 1))])

    @property
    def right_offset(self) -> np.ndarray:
        """Centre of the right camera in the left frame, (3,) float64."""
        return np.array([self.baseline_m, 0.0, 0.0])

    # --- projection ---
    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) points in the left frame -> (N, 2) float64 pixel coordinates (u, v).

        Points with z <= 0 give inf/nan; callers filter by depth first.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.fx * p[:, 0] / p[:, 2] + self.cx
            v = self.fy * p[:, 1] / p[:, 2] + self.cy
        return np.stack([u, v], axis=1)

    def disparity(self, z: np.ndarray) -> np.ndarray:
        """Stereo disparity in pixels of a point at depth z (metres): d = fx * baseline / z."""
        return self.fx * self.baseline_m / np.asarray(z, dtype=np.float64)

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) float64 ray directions through pixel centres, scaled so that z = 1."""
        u = np.arange(self.width, dtype=np.float64) + 0.5
        v = np.arange(self.height, dtype=np.float64) + 0.5
        uu, vv = np.meshgrid(u, v)
        return np.stack([(uu - self.cx) / self.fx, (vv - self.cy) / self.fy, np.ones_like(uu)], axis=-1)

    def backproject_depth(self, depth_m: np.ndarray) -> np.ndarray:
        """Depth map (H, W) of z in metres (0 = no return) -> (N, 3) float32 points, left frame.

        Pixels are taken in row-major order; non-finite and non-positive depths are skipped.
        """
        d = np.asarray(depth_m)
        if d.shape != (self.height, self.width):
            raise ValueError(f"depth map has shape {d.shape}, camera expects {(self.height, self.width)}")
        d = d.astype(np.float64, copy=False)
        valid = np.isfinite(d) & (d > 0)
        vv, uu = np.nonzero(valid)
        z = d[vv, uu]
        x = (uu + 0.5 - self.cx) / self.fx * z
        y = (vv + 0.5 - self.cy) / self.fy * z
        return np.stack([x, y, z], axis=1).astype(np.float32)

    def project_box3d_section(self, box3d: np.ndarray) -> np.ndarray:
        """2D box [x, y, w, h] of the 3D box's centre cross-section (the x-y rectangle at z = cz).

        This is A_proj of the paper's 2D-3D fusion (section IV-C). box3d: (6,) or (N, 6)
        [cx, cy, cz, sx, sy, sz]; returns (4,) or (N, 4) float64. Boxes with cz <= 0
        project to nan.
        """
        b = np.asarray(box3d, dtype=np.float64)
        single = b.ndim == 1
        b = b.reshape(-1, 6)
        cz = b[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            cz = np.where(cz > 0, cz, np.nan)
            x0 = self.fx * (b[:, 0] - b[:, 3] / 2) / cz + self.cx
            x1 = self.fx * (b[:, 0] + b[:, 3] / 2) / cz + self.cx
            y0 = self.fy * (b[:, 1] - b[:, 4] / 2) / cz + self.cy
            y1 = self.fy * (b[:, 1] + b[:, 4] / 2) / cz + self.cy
        out = np.stack([x0, y0, x1 - x0, y1 - y0], axis=1)
        return out[0] if single else out

    # --- serialisation ---
    def to_dict(self) -> dict:
        return {
            "width": int(self.width),
            "height": int(self.height),
            "fov_x_deg": float(self.fov_x_deg),
            "fov_y_deg": float(self.fov_y_deg),
            "baseline_m": float(self.baseline_m),
            "K": self.K.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Camera":
        try:
            cam = cls(int(d["width"]), int(d["height"]), float(d["fov_x_deg"]), float(d["fov_y_deg"]),
                      float(d.get("baseline_m", 0.4)))
        except KeyError as e:
            raise ValueError(f"camera description lacks the key {e.args[0]!r}") from None
        if "K" in d and not np.allclose(np.asarray(d["K"], dtype=np.float64), cam.K, rtol=1e-9, atol=1e-6):
            raise ValueError("camera K in the file disagrees with its perspective angles and resolution")
        return cam
