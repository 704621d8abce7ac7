"""Depth from the rectified binocular pair: semi-global matching (OpenCV StereoSGBM).

    m = StereoMatcher(camera)                      # the dataset's pair: right camera at +baseline
    z = m.depth(left, right)                       # (H, W) float64 metres, 0 = no depth
    z, win = m.depth_window(left, right, box2d)    # only around a 2D box (faster)
    points = StereoCloud(camera).bind(left, right) # callable box2d -> (N, 3) float32 cloud
    track = Track3D.from_default(camera, depth_sensor="stereo")
    out = track.update(left, points)               # Track3D computes only the tracked region

Build that Track3D for stereo depth (``depth_sensor="stereo"``): the stereo sensor's loop options
(``track3d.tracker.sensor_options("stereo")``; e.g. ``frustum_margin=0``: matched depth smears
past the silhouette, so a frustum cut wider than the 2D box collects background points, AO_3d
-0.024 with the default margin on held-out stereo sequences) and A3BoxNet's stereo model
(``track3d.boxnet.SENSOR_MODELS``).

Both cameras have the same intrinsics and orientation, the right one at x = +baseline
(`Camera.right_offset`), so a left pixel u matches the right pixel u - d and z = fx * B / d
(`Camera.disparity`). The search range is d in [0, fx * B / z_min]: a point nearer than
`z_min_m` cannot be matched.

What makes a disparity valid (the rest are holes, 0):
- SGBM's uniqueness test (best cost better than the second best by `uniqueness_ratio` %),
- left-right consistency (`lr_max_diff_px`: the right-to-left match must agree),
- speckle filtering (connected blobs smaller than `speckle_window` px are dropped),
- a texture test: the left image's local standard deviation over the matching block must be at
  least `min_texture_dn` (SGBM's smoothness term otherwise fills textureless regions with
  interpolated disparities, which look like data but are not),
- d >= `min_disparity_px` (z <= fx * B / min_disparity_px) and the depth within max_depth_m,
- u - d >= 0: a left pixel whose match would lie left of the right image is not seen by the
  right camera (the images are padded on the left before matching, so OpenCV's blind band of
  `numDisparities` columns at the left border shrinks to these pixels),
- not within `edge_erode_px` of a hole (8-neighbourhood, the image border is not a hole): the
  matching block of a pixel next to a hole straddles the body's edge, the sky, a shadow or an
  occlusion, and its disparity is the least reliable of the cloud (SGBM smears the body's
  disparity past its silhouette there).
Sub-pixel disparities: SGBM's 1/16-pixel interpolation of the matching cost.

Window mode: disparity is computed on the crop [x0 - D - m, x1 + m) x [y0 - m, y1 + m) of both
images (D = search range, m = margin), which contains every right pixel a box pixel can
match. Semi-global aggregation paths start at the crop border instead of the image border, so
inside the box the result can differ slightly from the full frame (tests bound it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .camera import Camera

__all__ = ["StereoParams", "StereoMatcher", "StereoCloud"]


@dataclass(frozen=True)
class StereoParams:
    """Matcher settings (defaults: the ones measured in docs/runtime.md, "Stereo")."""

    z_min_m: float = 1.5            # nearest depth searched (sets the disparity range)
    block_size: int = 5             # matching block (odd)
    uniqueness_ratio: int = 10      # %
    lr_max_diff_px: int = 1         # left-right consistency tolerance
    speckle_window: int = 100       # px; 0 = no speckle filter
    speckle_range_px: int = 2
    min_texture_dn: float = 2.0     # local sd of the left image below this -> no depth
    min_disparity_px: float = 1.0
    max_depth_m: float = 60.0
    mode: str = "3way"              # "3way" (default: as accurate as "sgbm" here, faster), "sgbm", "hh"
    window_margin_px: int = 16      # window mode: extra context around the box
    edge_erode_px: int = 1          # pixels this close to a hole are holes too (0 = off)

    def __post_init__(self) -> None:
        if self.block_size < 1 or self.block_size % 2 == 0:
            raise ValueError(f"block_size must be odd and >= 1, got {self.block_size}")
        if not self.z_min_m > 0:
            raise ValueError(f"z_min_m must be > 0, got {self.z_min_m}")
        if not (isinstance(self.edge_erode_px, (int, np.integer)) and 0 <= self.edge_erode_px <= 8):
            raise ValueError(f"edge_erode_px must be an integer in 0..8, got {self.edge_erode_px!r}")
        if self.mode not in _MODES:
            raise ValueError(f"mode must be one of {', '.join(_MODES)}, got {self.mode!r}")


_MODES = {"sgbm": cv2.STEREO_SGBM_MODE_SGBM, "hh": cv2.STEREO_SGBM_MODE_HH,
          "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY}


def _gray(img: np.ndarray) -> np.ndarray:
    # uint8 only, as every image of the loop (frames.check_image): a float or int64 image was cast
    # with wrap-around (433 -> 177, a silent wrong disparity) or crashed OpenCV's colour conversion
    a = np.asarray(img)
    if a.dtype != np.uint8 or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)) or min(a.shape[:2]) < 1:
        raise ValueError(f"stereo images must be (H, W, 3) or (H, W) uint8, got {a.shape} {a.dtype}")
    if a.ndim == 3:
        return cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(a)


class StereoMatcher:
    """Disparity and depth of a rectified pair of `camera` (identical cameras, horizontal baseline)."""

    def __init__(self, camera: Camera, params: StereoParams | None = None, **overrides):
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a track3d.Camera, got {type(camera).__name__}")
        p = params or StereoParams()
        if overrides:
            p = StereoParams(**{**p.__dict__, **overrides})
        self.camera = camera
        self.params = p
        self.fb = camera.fx * camera.baseline_m
        self.num_disparities = int(math.ceil(self.fb / p.z_min_m / 16.0)) * 16
        bs = p.block_size
        self._min_width = self.num_disparities + bs + 1
        self._sgbm = cv2.StereoSGBM_create(
            minDisparity=0, numDisparities=self.num_disparities, blockSize=bs, P1=8 * bs * bs, P2=32 * bs * bs,
            disp12MaxDiff=p.lr_max_diff_px, uniquenessRatio=p.uniqueness_ratio,
            speckleWindowSize=p.speckle_window, speckleRange=p.speckle_range_px, mode=_MODES[p.mode])

    def _check(self, left, right):
        gl, gr = _gray(left), _gray(right)
        shape = (self.camera.height, self.camera.width)
        if gl.shape != shape or gr.shape != shape:
            raise ValueError(f"stereo images are {gl.shape} and {gr.shape}, the camera is {shape}")
        return gl, gr

    def _disparity(self, gl: np.ndarray, gr: np.ndarray, pad: int = 0) -> np.ndarray:
        """Disparity (float32 px, 0 = invalid) of a (crop of a) gray pair.

        pad: black columns added to the left of both images before matching (the crop starts at
        the image's left border): OpenCV leaves the first `numDisparities` columns of its input
        without disparity, although a left pixel u only needs the right pixels u - d >= 0 of its
        own disparity d (a body at 30 m: d ~ 10 px, not the 208 px searched). Matches that land
        in the padding (u - d < 0: not seen by the right camera) are holes."""
        p = self.params
        if pad > 0:
            gl = cv2.copyMakeBorder(gl, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
            gr = cv2.copyMakeBorder(gr, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
        if gl.shape[1] < self._min_width:
            # OpenCV refuses (or crashes on) images not wider than the search range plus the block;
            # no pixel of such an image has its full search range anyway
            return np.zeros((gl.shape[0], gl.shape[1] - pad), np.float32)
        d = self._sgbm.compute(gl, gr).astype(np.float32) / 16.0
        if pad > 0:
            d = np.ascontiguousarray(d[:, pad:])
            gl = gl[:, pad:]
            u = np.arange(d.shape[1], dtype=np.float32)
            d[d > u[None, :]] = 0.0          # the match would lie left of the right image
        if p.min_texture_dn > 0:
            g = gl.astype(np.float32)
            k = (p.block_size, p.block_size)
            m = cv2.blur(g, k)
            var = cv2.blur(g * g, k) - m * m
            d[var < p.min_texture_dn ** 2] = 0.0
        d[d < max(p.min_disparity_px, self.fb / p.max_depth_m)] = 0.0
        if p.edge_erode_px > 0:
            k = 2 * p.edge_erode_px + 1
            # erode's default border is +inf: the image's (or the window's) border is not a hole
            inner = cv2.erode((d > 0).astype(np.uint8), np.ones((k, k), np.uint8))
            d[inner == 0] = 0.0
        return d

    def disparity(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """(H, W) float32 disparity in pixels of the whole frame, 0 = no match."""
        return self._disparity(*self._check(left, right), pad=self.num_disparities)

    def depth(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """(H, W) float64 z in metres of the whole frame (left grid), 0 = no depth."""
        return self._to_depth(self.disparity(left, right))

    def _to_depth(self, d: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.where(d > 0, self.fb / d.astype(np.float64), 0.0)

    def window(self, box2d) -> tuple[int, int, int, int] | None:
        """Pixel window (u0, u1, v0, v1) whose disparity this box needs computed; None if empty."""
        b = np.asarray(box2d, np.float64).reshape(-1)
        if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
            return None
        W, H, m = self.camera.width, self.camera.height, self.params.window_margin_px
        u0 = int(np.clip(math.floor(b[0]) - m, 0, W))
        u1 = int(np.clip(math.ceil(b[0] + b[2]) + m, 0, W))
        v0 = int(np.clip(math.floor(b[1]) - m, 0, H))
        v1 = int(np.clip(math.ceil(b[1] + b[3]) + m, 0, H))
        if u1 <= u0 or v1 <= v0:
            return None
        return u0, u1, v0, v1

    def depth_window(self, left: np.ndarray, right: np.ndarray, box2d) -> tuple[np.ndarray, tuple | None]:
        """Depth of the window around `box2d` only: ((v1-v0, u1-u0) float64 z, 0 = none,
        (u0, u1, v0, v1)); an empty or invalid box gives an empty array and None."""
        gl, gr = self._check(left, right)
        win = self.window(box2d)
        if win is None:
            return np.zeros((0, 0)), None
        u0, u1, v0, v1 = win
        c0 = max(0, u0 - self.num_disparities)   # every right pixel the window can match
        c1 = min(self.camera.width, max(u1, c0 + self._min_width))   # OpenCV's minimum width
        pad = self.num_disparities - (u0 - c0)     # > 0 only at the image's left border
        d = self._disparity(np.ascontiguousarray(gl[v0:v1, c0:c1]), np.ascontiguousarray(gr[v0:v1, c0:c1]), pad=pad)
        return self._to_depth(d[:, u0 - c0:u1 - c0]), win

    def points_window(self, left: np.ndarray, right: np.ndarray, box2d) -> np.ndarray:
        """(N, 3) float32 cloud (left frame) of the window around `box2d`."""
        z, win = self.depth_window(left, right, box2d)
        if win is None:
            return np.zeros((0, 3), np.float32)
        u0, _, v0, _ = win
        vv, uu = np.nonzero(z > 0)
        zz = z[vv, uu]
        c = self.camera
        x = (uu + u0 + 0.5 - c.cx) / c.fx * zz
        y = (vv + v0 + 0.5 - c.cy) / c.fy * zz
        return np.stack([x, y, zz], axis=1).astype(np.float32)


class StereoCloud:
    """Point clouds of the tracked region from a stereo pair, for `Track3D.update(image, points)`.

        cloud = StereoCloud(camera)
        out = track.update(left, cloud.bind(left, right))   # disparity only around the 2D box
    """

    def __init__(self, camera: Camera, params: StereoParams | None = None, **overrides):
        self.matcher = StereoMatcher(camera, params, **overrides)

    def bind(self, left: np.ndarray, right: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A callable box2d -> (N, 3) float32 cloud of this pair around the box."""
        gl, gr = self.matcher._check(left, right)

        def points(box2d) -> np.ndarray:
            return self.matcher.points_window(gl, gr, box2d)
        return points
