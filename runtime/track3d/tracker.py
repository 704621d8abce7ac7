"""The Track3D loop (paper section IV): 2D tracker -> frustum -> 3D box estimator -> 2D-3D fusion.

    t = Track3D.create(camera, tracker="kcf", estimator="baseline")
    t.init(image, box2d, category)          # optionally points=... for an initial 3D box
    out = t.update(image, points)           # -> TrackResult(box2d, box2d_raw, box3d, status, ...)

Per frame: the 2D tracker gives A_2d; the frustum proposal takes the cloud's points whose
projection falls in A_2d (1 <= z <= 45 m); the estimator turns them into a 3D box; fusion
reports A = 0.3 A_proj + 0.7 A_2d and hands it back to the 2D tracker as its state for the
next frame (``correct(box)`` when the tracker has it: SiamFC moves its search centre and
size, OpenCV trackers ignore it by default, see trackers2d).

Nothing in the loop raises on bad sensor data: a lost 2D target is status "lost"; a frustum
too thin to estimate from (fewer than `min_points` points, or all of them within 1 cm of each
other, e.g. a quantised or stuck cloud) or an estimate that is not a finite box of positive size
is status "no_points", as is a frustum the estimator refuses (ValueError, e.g. points spanning
more than A3BoxNet answers for); the 3D box then keeps the last estimate (nan before the first one).
Caller errors raise ValueError (the checks live in track3d.frames): an image that is not
(H, W, 3) uint8 or not the camera's size, a cloud that is not (N, 3), a category that is not an
integer in -1 .. categories - 1, an init box that is not finite, has no positive size, does not
overlap the image or is more than 10x the image.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .estimators import BoxEstimator, create_estimator
from .frames import MAX_COORD_M, check_category, check_image, check_init_box
from .frustum import Z_MAX, Z_MIN, extract_frustum_bounds
from .fusion import WEIGHT_3D, fuse
from .trackers2d import Tracker2D, create_tracker

__all__ = ["Track3D", "TrackResult", "STATUSES", "TRACKING", "NO_POINTS", "LOST", "STAGES", "MIN_POINTS"]

TRACKING, NO_POINTS, LOST = "tracking", "no_points", "lost"
STATUSES = (TRACKING, NO_POINTS, LOST)
STAGES = ("track2d", "frustum", "box3d", "fusion", "total")
MIN_POINTS = 16          # the fewest frustum points A3BoxNet was trained on
MIN_SPREAD_M = 0.01      # a frustum whose points all lie within 1 cm holds no shape


@dataclass
class TrackResult:
    """One frame's output. box2d (4,) float64 is the reported box (fused when fusion is on);
    box2d_raw (4,) the 2D tracker's own box; box3d (6,) float64 [cx, cy, cz, sx, sy, sz];
    status one of STATUSES; num_points the frustum size; ms per-stage milliseconds (STAGES)."""

    box2d: np.ndarray
    box2d_raw: np.ndarray
    box3d: np.ndarray
    status: str
    num_points: int
    ms: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == TRACKING


def _valid_box2d(b: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0)


class Track3D:
    """The 3D tracker: one 2D tracker, one 3D box estimator, the camera of the point clouds."""

    def __init__(self, camera: Camera, tracker2d: Tracker2D, estimator: BoxEstimator, fusion: bool = True,
                 weight_3d: float = WEIGHT_3D, z_range: tuple[float, float] = (Z_MIN, Z_MAX),
                 min_points: int = MIN_POINTS):
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a track3d.Camera, got {type(camera).__name__}")
        if not 0.0 <= float(weight_3d) <= 1.0:
            raise ValueError(f"weight_3d must be in [0, 1], got {weight_3d}")
        z0, z1 = (float(z) for z in z_range)
        if not (0.0 <= z0 < z1):
            raise ValueError(f"z_range must be (near, far) with 0 <= near < far, got {z_range}")
        if int(min_points) < 1:
            raise ValueError(f"min_points must be >= 1, got {min_points}")
        self.camera = camera
        self.tracker2d = tracker2d
        self.estimator = estimator
        self.fusion = bool(fusion)
        self.weight_3d = float(weight_3d)
        self.z_range = (z0, z1)
        self.min_points = int(min_points)
        self._size = (camera.width, camera.height)
        self._M = camera.M
        self._correct = getattr(tracker2d, "correct", None)
        self.category = -1
        self.box2d = np.full(4, np.nan)
        self.box3d = np.full(6, np.nan)

    def __repr__(self) -> str:
        return (f"Track3D({self.tracker2d!r}, {self.estimator!r}, fusion={self.fusion}, "
                f"weight_3d={self.weight_3d})")

    # --- construction by names -----------------------------------------------------------------
    @classmethod
    def create(cls, camera: Camera, tracker: str = "kcf", estimator: str = "baseline",
               tracker_options: dict | None = None, estimator_options: dict | None = None,
               **options) -> "Track3D":
        """Build from registry names; `options` go to Track3D (fusion, weight_3d, z_range)."""
        return cls(camera, create_tracker(tracker, **(tracker_options or {})),
                   create_estimator(estimator, **(estimator_options or {})), **options)

    @classmethod
    def from_default(cls, camera: Camera, threads: int = 1, **options) -> "Track3D":
        """The shipped models: SiamFC (edge variant) + A3BoxNet, on `threads` CPU threads.

        Raises TrackerUnavailable / EstimatorUnavailable when the models are not shipped.
        """
        return cls(camera, create_tracker("siamfc-edge", threads=threads),
                   create_estimator("a3boxnet", threads=threads), **options)

    # --- the loop --------------------------------------------------------------------------------
    def _frustum(self, points: np.ndarray, box2d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(frustum points, their (2, 3) [min; max]) from one C++ pass; the points are finite."""
        return extract_frustum_bounds(points, box2d, self._M, *self.z_range)

    def _estimate(self, pts: np.ndarray, bounds: np.ndarray) -> np.ndarray | None:
        # The checks use the frustum pass's bounds: no second pass over a large frustum.
        if len(pts) < self.min_points:
            return None
        lo, hi = bounds
        if (hi - lo).max() < MIN_SPREAD_M or lo.min() < -MAX_COORD_M or hi.max() > MAX_COORD_M:
            return None
        try:
            b = np.asarray(self.estimator.estimate(pts, self.category), dtype=np.float64).reshape(-1)
        except ValueError:  # points outside the estimator's domain (e.g. A3BoxNet's extent)
            return None
        if b.shape != (6,) or not np.all(np.isfinite(b)) or np.any(b[3:] <= 0.0):
            return None
        return b

    def init(self, image: np.ndarray, box2d: np.ndarray, category: int = -1,
             points: np.ndarray | None = None) -> None:
        """Start on `image` with the target in `box2d` [x, y, w, h]; category: coarse category.

        points: the frame's cloud (N, 3), optional; when given the first 3D box is estimated
        from its frustum so that a later empty frustum has a box to keep.
        """
        b = check_init_box(box2d, self._size)
        category = check_category(category, getattr(self.estimator, "num_categories", None))
        image = check_image(image, self._size)
        self.category = category
        self.tracker2d.init(image, b)
        self.box2d = b.copy()
        self.box3d = np.full(6, np.nan)
        if points is not None:
            est = self._estimate(*self._frustum(points, b))
            if est is not None:
                self.box3d = est

    def update(self, image: np.ndarray, points: np.ndarray) -> TrackResult:
        """Track into the next frame: image (H, W, 3) uint8 RGB, points (N, 3) float32 cloud."""
        ms: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        t0 = time.perf_counter()
        image = check_image(image, self._size)
        ok, raw = self.tracker2d.update(image)
        raw = np.asarray(raw, dtype=np.float64).reshape(-1)
        t1 = time.perf_counter()
        ms["track2d"] = (t1 - t0) * 1e3
        if not ok or raw.shape != (4,) or not _valid_box2d(raw):
            # Lost in 2D: report the last box, keep the last 3D estimate.
            raw = raw if raw.shape == (4,) and _valid_box2d(raw) else self.box2d.copy()
            ms["total"] = (time.perf_counter() - t0) * 1e3
            return TrackResult(self.box2d.copy(), raw, self.box3d.copy(), LOST, 0, ms)

        pts, bounds = self._frustum(points, raw)
        t2 = time.perf_counter()
        ms["frustum"] = (t2 - t1) * 1e3
        est = self._estimate(pts, bounds)
        t3 = time.perf_counter()
        ms["box3d"] = (t3 - t2) * 1e3
        status = TRACKING
        if est is None:
            status = NO_POINTS
        else:
            self.box3d = est
        box = raw
        if self.fusion and est is not None:
            box = fuse(raw, est, self.camera, self.weight_3d)
            if self._correct is not None:
                self._correct(box)
        self.box2d = box.copy()
        t4 = time.perf_counter()
        ms["fusion"] = (t4 - t3) * 1e3
        ms["total"] = (t4 - t0) * 1e3
        return TrackResult(box.copy(), raw.copy(), self.box3d.copy(), status, int(len(pts)), ms)
