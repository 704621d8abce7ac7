"""Pinhole camera of the dataset: the ONE implementation of the camera formulas.

Frame: the left camera, OpenCV style (x right, y down, z forward, metres).
Pixel coordinates are continuous: pixel (i, j) covers u in [i, i+1), v in [j, j+1),
so its centre is (i + 0.5, j + 0.5). By default the intrinsics follow the paper's eq. (1):
fx = W / (2 tan(ax/2)), fy = H / (2 tan(ay/2)), cx = W/2, cy = H/2 (the simulator's cameras).
A calibrated camera (``Camera.from_intrinsics``) carries its own fx, fy, cx, cy (the angles
are then derived from them, for information) and optionally OpenCV distortion coefficients
``dist`` (k1, k2, p1, p2[, k3...]): its images are undistorted to the pinhole K
(``undistort_image``; Track3D does it on every frame), everything else uses K.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["Camera"]


@dataclass(frozen=True)
class Camera:
    """Two identical pinhole cameras; the right one sits at x = +baseline_m (None: no known
    pair, a single camera; stereo matching then refuses it). 0.4 m is the simulator's."""

    width: int
    height: int
    fov_x_deg: float
    fov_y_deg: float
    baseline_m: float | None = 0.4
    intrinsics: tuple[float, float, float, float] | None = None   # (fx, fy, cx, cy) pixels; None: eq. (1)
    dist: tuple[float, ...] | None = None                          # OpenCV distortion coefficients

    def __post_init__(self) -> None:
        w, h = _resolution(self.width, self.height)
        object.__setattr__(self, "width", w)
        object.__setattr__(self, "height", h)
        for name in ("fov_x_deg", "fov_y_deg"):
            v = float(getattr(self, name))
            if not (0.0 < v < 180.0) or not math.isfinite(v):
                raise ValueError(f"camera {name} must be in (0, 180) degrees, got {v}")
        if self.baseline_m is not None:
            try:
                b = float(self.baseline_m)
            except (TypeError, ValueError):
                raise ValueError(f"camera baseline_m must be a number of metres or None, got {self.baseline_m!r}") \
                    from None
            if not (math.isfinite(b) and b > 0.0):   # 0 or < 0 had failed deep in OpenCV's matcher
                raise ValueError(f"camera baseline_m must be a finite distance > 0 m (or None: no stereo pair), "
                                 f"got {self.baseline_m}")
            object.__setattr__(self, "baseline_m", b)
        if self.intrinsics is not None:
            k = tuple(float(v) for v in self.intrinsics)
            if len(k) != 4 or not all(math.isfinite(v) for v in k) or k[0] <= 0 or k[1] <= 0:
                raise ValueError(f"camera intrinsics are (fx, fy, cx, cy) with fx, fy > 0, got {self.intrinsics}")
            object.__setattr__(self, "intrinsics", k)
        if self.dist is not None:
            d = tuple(float(v) for v in self.dist)
            if len(d) not in (4, 5, 8, 12, 14) or not all(math.isfinite(v) for v in d):
                raise ValueError(f"distortion coefficients are 4, 5, 8, 12 or 14 finite numbers "
                                 f"(OpenCV order k1, k2, p1, p2, k3, ...), got {self.dist}")
            object.__setattr__(self, "dist", d if any(d) else None)

    @classmethod
    def from_intrinsics(cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                        dist=None, baseline_m: float | None = None) -> "Camera":
        """A calibrated camera: focal lengths and principal point in pixels (continuous pixel
        coordinates, pixel i spans [i, i+1): OpenCV's calibration gives cx for pixel centres at
        integers, add 0.5 to it), `dist` OpenCV's distortion coefficients or None, `baseline_m`
        the stereo pair's baseline in metres (None, the default: no pair; stereo depth needs it,
        which is why it is not defaulted to the simulator's 0.4 m)."""
        w, h = _resolution(width, height)
        try:
            vals = [float(v) for v in (fx, fy, cx, cy)]
        except (TypeError, ValueError):
            raise ValueError(f"fx, fy, cx, cy must be numbers, got {fx!r}, {fy!r}, {cx!r}, {cy!r}") from None
        if not all(math.isfinite(v) for v in vals):   # nan had been told "fov_x_deg must be in (0, 180)"
            raise ValueError(f"fx, fy, cx, cy must be finite, got fx={fx}, fy={fy}, cx={cx}, cy={cy}")
        if fx <= 0 or fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={fx}, fy={fy}")
        ax = math.degrees(2.0 * math.atan(w / (2.0 * fx)))
        ay = math.degrees(2.0 * math.atan(h / (2.0 * fy)))
        return cls(w, h, ax, ay, baseline_m, (float(fx), float(fy), float(cx), float(cy)),
                   None if dist is None else tuple(np.asarray(dist, dtype=np.float64).reshape(-1).tolist()))

    @classmethod
    def from_K(cls, width: int, height: int, K, dist=None, baseline_m: float | None = None) -> "Camera":
        """A calibrated camera from its (3, 3) intrinsic matrix (no skew); as from_intrinsics."""
        k = _matrix3(K)
        if abs(k[0, 1]) > 1e-9 or np.any(np.abs(k[2] - [0, 0, 1]) > 1e-9) or abs(k[1, 0]) > 1e-9:
            raise ValueError("K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew)")
        return cls.from_intrinsics(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], dist, baseline_m)

    @property
    def calibrated(self) -> bool:
        """True when K was given (from_intrinsics / from_K), False for an eq.-(1) camera."""
        return self.intrinsics is not None

    @property
    def tan_half(self) -> tuple[float, float]:
        """(tan(ax/2), tan(ay/2)): half the image over the focal length, per axis."""
        if self.intrinsics is None:
            return (math.tan(math.radians(self.fov_x_deg) / 2), math.tan(math.radians(self.fov_y_deg) / 2))
        return (self.width / (2.0 * self.fx), self.height / (2.0 * self.fy))

    @cached_property
    def _undistort_maps(self):
        import cv2

        return cv2.initUndistortRectifyMap(self.K, np.asarray(self.dist), None, self.K,
                                           (self.width, self.height), cv2.CV_16SC2)

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """The image as the pinhole K would see it (bilinear remap); unchanged without `dist`."""
        if self.dist is None:
            return image
        import cv2

        m1, m2 = self._undistort_maps
        return cv2.remap(image, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

    @classmethod
    def from_fov(cls, width: int, height: int, fov_x_deg: float, baseline_m: float | None = 0.4) -> "Camera":
        """Square pixels: the vertical perspective angle follows from the horizontal one. The
        simulator's camera (eq. 1), with its 0.4 m baseline unless given."""
        width, height = _resolution(width, height)  # before the division below
        fy_half = math.atan(height / width * math.tan(math.radians(fov_x_deg) / 2.0))
        return cls(width, height, float(fov_x_deg), math.degrees(2.0 * fy_half), baseline_m)

    # --- intrinsics (paper eq. 1) ---
    @property
    def fx(self) -> float:
        if self.intrinsics is not None:
            return self.intrinsics[0]
        return self.width / (2.0 * math.tan(math.radians(self.fov_x_deg) / 2.0))

    @property
    def fy(self) -> float:
        if self.intrinsics is not None:
            return self.intrinsics[1]
        return self.height / (2.0 * math.tan(math.radians(self.fov_y_deg) / 2.0))

    @property
    def cx(self) -> float:
        if self.intrinsics is not None:
            return self.intrinsics[2]
        return self.width / 2.0

    @property
    def cy(self) -> float:
        if self.intrinsics is not None:
            return self.intrinsics[3]
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
        return np.array([self._baseline(), 0.0, 0.0])

    def _baseline(self) -> float:
        if self.baseline_m is None:
            raise ValueError("this camera has no stereo pair (baseline_m None): give it baseline_m")
        return float(self.baseline_m)

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
        return self.fx * self._baseline() / np.asarray(z, dtype=np.float64)

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
        """Plain dict; a calibrated camera adds "calibrated": true (its K is authoritative,
        the angles informational) and "dist" when it has distortion."""
        d = {
            "width": int(self.width),
            "height": int(self.height),
            "fov_x_deg": float(self.fov_x_deg),
            "fov_y_deg": float(self.fov_y_deg),
            "baseline_m": None if self.baseline_m is None else float(self.baseline_m),
            "K": self.K.tolist(),
        }
        if self.calibrated:
            d["calibrated"] = True
        if self.dist is not None:
            d["dist"] = list(self.dist)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Camera":
        """Inverse of to_dict. A dict with a K and "calibrated": true, or with a K and no
        perspective angles, is a calibrated camera (any fx, fy, cx, cy, optional "dist");
        otherwise the angles define K (eq. 1) and a K given next to them must agree. A key
        other than DICT_KEYS is refused (a "baseline" for "baseline_m" had been ignored: no
        stereo pair, silently)."""
        if not isinstance(d, dict):
            raise ValueError(f"a camera description is a JSON object, got {type(d).__name__}")
        unknown = sorted(str(k) for k in d if k not in DICT_KEYS)
        if unknown:
            import difflib

            near = difflib.get_close_matches(unknown[0], DICT_KEYS, n=1, cutoff=0.6)
            raise ValueError(f"camera description has the unknown key {unknown[0]!r}"
                             + (f" (did you mean {near[0]!r}?)" if near else "")
                             + (f" and {len(unknown) - 1} more" if len(unknown) > 1 else "")
                             + f"; the known keys: {', '.join(DICT_KEYS)}")
        if "K" in d and (d.get("calibrated") or "fov_x_deg" not in d or d.get("dist")):
            try:
                # a calibrated camera's file without a baseline has no known pair
                return cls.from_K(d["width"], d["height"], d["K"], d.get("dist"), d.get("baseline_m"))
            except KeyError as e:
                raise ValueError(f"camera description lacks the key {e.args[0]!r}") from None
        try:
            cam = cls(d["width"], d["height"], float(d["fov_x_deg"]), float(d["fov_y_deg"]),
                      d.get("baseline_m", 0.4))
        except KeyError as e:
            raise ValueError(f"camera description lacks the key {e.args[0]!r}") from None
        if "K" in d and not np.allclose(_matrix3(d["K"]), cam.K, rtol=1e-9, atol=1e-6):
            raise ValueError("camera K in the file disagrees with its perspective angles and resolution "
                             "(a calibrated K needs \"calibrated\": true)")
        return cam


# The keys of a camera description (to_dict / from_dict, dataset.json "camera"): width, height
# (pixels), fov_x_deg, fov_y_deg (degrees, eq. 1), baseline_m (metres or null), K (3x3 pixels),
# calibrated (K authoritative), dist (OpenCV distortion coefficients).
DICT_KEYS = ("width", "height", "fov_x_deg", "fov_y_deg", "baseline_m", "K", "calibrated", "dist")


def _resolution(width, height) -> tuple[int, int]:
    """(width, height) as positive whole numbers of pixels: 640.5 or "640" would otherwise be
    truncated, kept as a float or parsed without a word (a camera one pixel off puts every
    frustum in the wrong place)."""
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not math.isfinite(v) or v != int(v):
            raise ValueError(f"camera {name} must be a whole number of pixels, got {v!r}")
    if width <= 0 or height <= 0:
        raise ValueError(f"camera resolution must be positive, got {width}x{height}")
    return int(width), int(height)


def _matrix3(K) -> np.ndarray:
    """K as a finite (3, 3) float64 array, or ValueError saying what it is instead."""
    try:
        k = np.asarray(K, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"K must be a finite 3x3 matrix of numbers, got {K!r:.80}") from None
    if k.shape != (3, 3):
        raise ValueError(f"K must be a finite 3x3 matrix, got shape {k.shape}")
    if not np.all(np.isfinite(k)):
        raise ValueError("K must be a finite 3x3 matrix, it holds NaN or inf")
    return k
