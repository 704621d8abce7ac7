"""Depth from the rectified binocular pair: semi-global matching (OpenCV StereoSGBM).

    m = StereoMatcher(camera)                      # the dataset's pair: right camera at +baseline
    z = m.depth(left, right)                       # (H, W) float64 metres, 0 = no depth
    z, win = m.depth_window(left, right, box2d)    # only around a 2D box (faster)
    points = StereoCloud(camera).bind(left, right) # callable box2d -> (N, 3) float32 cloud
    track = Track3D.from_default(camera, depth_sensor="stereo")
    out = track.update(left, points)               # Track3D computes only the tracked region

Build that Track3D for stereo depth (``depth_sensor="stereo"``): the stereo sensor's loop options
(``track3d.sensor_options.sensor_options("stereo")``; e.g. ``frustum_margin=0``: matched depth smears
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

Following the body's depth (`StereoCloud`, `follow_depth`): after a window with returns, the next
searches only disparities [0, fx B / (z / k)), z the nearest of the body's depths (a 2% quantile),
k = `follow_depth` (1.5): a body at 15 m needs 48 disparities, not the 208 down to z_min_m, and
the window's search strip shrinks with them (the stereo loop 26.0 -> 13.5 ms a frame on the
README's stereo test split; docs/runtime.md "Stereo"). The search still starts at 0 so that the
sky behind the body matches as sky; a match at the search's near end is a hole (a surface nearer
than the search snaps there); a followed search that finds fewer than FOLLOW_MIN_POINTS returns
(or fewer returns per pixel than FOLLOW_MIN_SHARE of the last window's: a body nearer than the
search reaches is matched at wrong disparities, not only left with holes) is repeated over the
full range.

Binned rows (`max_match_px`, clouds only: `points_window`, `StereoCloud`): a window of more
pixels than `max_match_px` is matched with its rows averaged in bands of 2 (or 4, at most) from
the image's top, so a large near body costs a half or a quarter of the matching; the columns stay
the camera's, and with them the disparity's precision (depth is the disparity along a row). A
band's return is one point at the band's centre row. The follow rule compares returns per pixel
of the grid matched on. `depth`, `depth_window` and `disparity` match every row.
`max_match_cost` bounds what matching costs (`match_cost`: pixels x (disparities searched +
MATCH_PX_DISPARITIES), about proportional to the matcher's time) instead of a window's size: only
the dearest windows, a large near body or a full-range search over a wide box, are binned, in
bands of up to MAX_COST_BAND_ROWS rows. In `StereoCloud` it is a budget per update: a followed
search repeated over the full range gets what the first match left (in coarser bands), and when
even the coarsest bands do not fit, the update has no cloud (the next one searches the full range
with the whole budget) rather than the followed search's untrusted one. So an update's matching
costs at most the cap, unless one window costs more than MAX_COST_BAND_ROWS times it (the whole
640 x 480 frame over the full range: 78.6 M; such a window is matched in the coarsest bands). A
count, not a time: the same inputs give the same clouds on every machine.

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
    window_margin_px: int = 32      # window mode: extra context around the box (32: the loop's AO_3d +0.006
                                    # over 16 on 14 stereo splits, the matching ~25% dearer; docs/runtime.md)
    edge_erode_px: int = 1          # pixels this close to a hole are holes too (0 = off)
    follow_depth: float = 1.5       # StereoCloud: search only down to the nearest depth the body can be
                                    # at, the last window's nearest z / k (0: off, always the full range
                                    # down to z_min_m)
    max_match_px: int = 0           # clouds (points_window, StereoCloud): a window of more pixels than this
                                    # is matched with its rows averaged in pairs (or fours) until it has at
                                    # most this many (0: off, every row matched)
    max_match_cost: int = 0         # clouds: the matching budget of a call (StereoCloud: of an update, its
                                    # retry included): a window dearer than this (`binned_cost`: pixels x
                                    # (disparities + MATCH_PX_DISPARITIES)) is matched with its rows
                                    # averaged in bands of 2, 4 or 8 until it fits: a bound on the loop's
                                    # worst frames (0: off)

    def __post_init__(self) -> None:
        for name in ("block_size", "uniqueness_ratio", "lr_max_diff_px", "speckle_window", "speckle_range_px",
                     "window_margin_px", "max_match_px", "max_match_cost"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        for name in ("z_min_m", "min_texture_dn", "min_disparity_px", "max_depth_m", "follow_depth"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v) \
                    or v < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        if not self.max_depth_m > 0:
            raise ValueError(f"max_depth_m must be > 0, got {self.max_depth_m}")
        if self.block_size < 1 or self.block_size % 2 == 0:
            raise ValueError(f"block_size must be odd and >= 1, got {self.block_size}")
        if not self.z_min_m > 0:
            raise ValueError(f"z_min_m must be > 0, got {self.z_min_m}")
        if not (isinstance(self.edge_erode_px, (int, np.integer)) and 0 <= self.edge_erode_px <= 8):
            raise ValueError(f"edge_erode_px must be an integer in 0..8, got {self.edge_erode_px!r}")
        if self.mode not in _MODES:
            raise ValueError(f"mode must be one of {', '.join(_MODES)}, got {self.mode!r}")
        if 0.0 < self.follow_depth < 1.0:   # finite and >= 0: checked above
            raise ValueError(f"follow_depth must be 0 (off) or >= 1, got {self.follow_depth!r}")


RANGE_END_PX = 1.0   # a narrowed search's matches this close to its near end are holes (StereoCloud)
# The matcher's per-pixel work that does not grow with the disparities searched (the texture test,
# the cost's preparation, the filters), in disparities' worth: OpenCV's 3-way SGBM on one core took
# about 68 ns a pixel plus 1.44 ns a pixel and disparity (windows of 9,000-152,000 px, 32-208
# disparities; an Intel Xeon, 2026-11), so a window's time is about its pixels x (n + 48).
MATCH_PX_DISPARITIES = 48


# max_match_px bins rows in bands of at most 4; a cost budget may go to 8 (a retried full-range
# search in what the first match left): past that a band spans a body's features (8 rows of a
# 100-row body) and the update goes without a cloud instead (StereoCloud)
MAX_PX_BAND_ROWS = 4
MAX_COST_BAND_ROWS = 8
# Averaging a window's rows into bands reads every pixel of both crops (the search strip included)
# once: about 4 of the cost's units per source pixel (the same host and windows, k = 2-8; without
# it a band grid's matching was under-costed by 6-42% as k went 2 -> 8, and a budget's binned
# updates took the longest)
BAND_SOURCE_COST = 4


def _match_cost(pixels: int, n: int) -> int:
    """The matching cost of `pixels` searched over disparities [0, n)."""
    return int(pixels) * (int(n) + MATCH_PX_DISPARITIES)

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
        if camera.baseline_m is None:
            raise ValueError("stereo depth needs the pair's baseline: give the camera baseline_m "
                             "(e.g. Camera.from_intrinsics(..., baseline_m=0.12))")
        if camera.dist is not None:
            raise ValueError("stereo matching takes a rectified pair: rectify both images (e.g. "
                             "cv2.stereoRectify) and give the rectified camera, without distortion")
        self.camera = camera
        self.params = p
        self.fb = camera.fx * camera.baseline_m
        self.num_disparities = int(math.ceil(self.fb / p.z_min_m / 16.0)) * 16
        self._sgbm: dict[tuple[int, int], cv2.StereoSGBM] = {}

    def _matcher(self, n: int, rows: int = 1) -> cv2.StereoSGBM:
        """OpenCV's SGBM for disparities [0, n) (n a multiple of 16) on the pair with `rows` rows
        averaged into one (the speckle filter's blob size is in that grid's pixels)."""
        m = self._sgbm.get((n, rows))
        if m is None:
            p, bs = self.params, self.params.block_size
            m = self._sgbm[n, rows] = cv2.StereoSGBM_create(
                minDisparity=0, numDisparities=n, blockSize=bs, P1=8 * bs * bs, P2=32 * bs * bs,
                disp12MaxDiff=p.lr_max_diff_px, uniquenessRatio=p.uniqueness_ratio,
                speckleWindowSize=p.speckle_window // rows, speckleRange=p.speckle_range_px,
                mode=_MODES[p.mode])
        return m

    def disparities_to(self, z_near: float) -> int:
        """How many disparities, [0, n), to search for depths from `z_near` metres to infinity: the
        multiple of 16 (OpenCV's) past fx B / z_near, at most the full range (fx B / z_min_m). The
        search always starts at 0: the sky's texture behind the body then finds its own match
        (d ~ 0, dropped as too far) instead of a false one among the body's disparities (a search
        cut to the body's depths at both ends gave 2,000 such points around a body at 15 m)."""
        if not (np.isfinite(z_near) and z_near > 0.0):
            return self.num_disparities
        return min(int(math.ceil((self.fb / z_near + 1.0) / 16.0)) * 16, self.num_disparities)

    def _check(self, left, right):
        gl, gr = _gray(left), _gray(right)
        shape = (self.camera.height, self.camera.width)
        if gl.shape != shape or gr.shape != shape:
            raise ValueError(f"stereo images are {gl.shape} and {gr.shape}, the camera is {shape}")
        return gl, gr

    def _min_width(self, n: int) -> int:
        return n + self.params.block_size + 1

    def _disparity(self, gl: np.ndarray, gr: np.ndarray, pad: int = 0, n: int | None = None,
                   rows: int = 1) -> np.ndarray:
        """Disparity (float32 px, 0 = invalid) of a (crop of a) gray pair, searched over [0, n)
        (default the full range). rows: each row of the pair is that many of the camera's averaged
        (the columns, and so the disparities, are the camera's).

        pad: black columns added to the left of both images before matching (the crop starts at
        the image's left border): OpenCV leaves the first n columns of its input
        without disparity, although a left pixel u only needs the right pixels u - d >= 0 of its
        own disparity d (a body at 30 m: d ~ 10 px, not the 208 px searched). Matches that land
        in the padding (u - d < 0: not seen by the right camera) are holes."""
        p = self.params
        n = self.num_disparities if n is None else int(n)
        if pad > 0:
            gl = cv2.copyMakeBorder(gl, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
            gr = cv2.copyMakeBorder(gr, 0, 0, pad, 0, cv2.BORDER_CONSTANT, value=0)
        if gl.shape[1] < self._min_width(n):
            # OpenCV refuses (or crashes on) images not wider than the search range plus the block;
            # no pixel of such an image has its full search range anyway
            return np.zeros((gl.shape[0], gl.shape[1] - pad), np.float32)
        d = self._matcher(n, rows).compute(gl, gr).astype(np.float32) / 16.0
        if n < self.num_disparities:
            # a surface nearer than a narrowed search reaches snaps to its end, consistently in
            # both directions: the end is a hole
            d[d > n - 1 - RANGE_END_PX] = 0.0
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

    def match_cost(self, window: tuple[int, int, int, int], n: int | None = None) -> int:
        """The matching cost of a `window` (u0, u1, v0, v1) searched over disparities [0, n) (default
        the full range), every row: its pixels x (n + MATCH_PX_DISPARITIES)."""
        u0, u1, v0, v1 = window
        n = self.num_disparities if n is None else int(n)
        return _match_cost((u1 - u0) * (v1 - v0), n)

    def _bands(self, window: tuple[int, int, int, int], k: int) -> tuple[int, int]:
        """The rows (v0, v1) of the grid of k-row bands from the image's top that cover `window`'s
        rows (grid row i averages the camera's rows k i .. k i + k - 1; only whole bands)."""
        v0, v1 = window[2], window[3]
        return (v0, v1) if k == 1 else (v0 // k, min(-(-v1 // k), self.camera.height // k))

    def _columns(self, window: tuple[int, int, int, int], n: int) -> tuple[int, int]:
        """The columns [c0, c1) of both images a window searched over [0, n) is matched on: every
        right pixel its left pixels can match, at least OpenCV's minimum width."""
        c0 = max(0, window[0] - n)
        return c0, min(self.camera.width, max(window[1], c0 + self._min_width(n)))

    def binned_cost(self, window: tuple[int, int, int, int], n: int | None = None, k: int = 1) -> int:
        """The matching cost of `window` searched over [0, n) (default the full range) with its
        rows averaged in bands of k: the band grid's pixels x (n + MATCH_PX_DISPARITIES), and for
        k > 1 the averaging, BAND_SOURCE_COST per pixel of the crop's rows (`_columns`)."""
        b0, b1 = self._bands(window, k)
        n = self.num_disparities if n is None else int(n)
        rows = max(0, b1 - b0)
        cost = _match_cost((window[1] - window[0]) * rows, n)
        if k > 1:
            c0, c1 = self._columns(window, n)
            cost += BAND_SOURCE_COST * (c1 - c0) * rows * k
        return cost

    def rows_for(self, window: tuple[int, int, int, int], n: int | None = None,
                 budget: int | None = None) -> int:
        """How many rows a cloud's `window` (u0, u1, v0, v1), searched over disparities [0, n)
        (default the full range), is matched with averaged into one: the fewest (1, 2, 4) that leave
        it at most `max_match_px` pixels (px / k), and the fewest (1, 2, 4, 8) whose band grid costs
        at most `budget` (`binned_cost`; default `max_match_cost`, 0: no bound), the larger of the
        two; 0 when the coarsest bands cost more than the budget. Rows, not columns: depth is the
        disparity along a row, its precision stays the camera's (at 16384 px, bands of rows cost
        the loop 0.02 AO_3d, 2 x 2 pixel blocks 0.06; docs/runtime.md "Stereo")."""
        cap, (u0, u1, v0, v1) = self.params.max_match_px, window
        if budget is None:
            budget = self.params.max_match_cost or None
        k = 1
        while k < MAX_PX_BAND_ROWS and cap > 0 and (u1 - u0) * (v1 - v0) > cap * k:
            k *= 2
        if budget is not None:
            while self.binned_cost(window, n, k) > budget:
                if k >= MAX_COST_BAND_ROWS:
                    return 0
                k *= 2
        return k

    def _window_disparity(self, left: np.ndarray, right: np.ndarray, box2d, n: int | None,
                          binned: bool = False, budget: int | None = None, strict: bool = False
                          ) -> tuple[np.ndarray, tuple | None, int, int]:
        """((v1-v0, u1-u0) float32 disparity of the window around `box2d`, 0 = none, its
        (u0, u1, v0, v1), k, the rows averaged into one, and what it cost, `binned_cost`); an
        invalid box: an empty array, None, 1, 0. binned: k = `rows_for(window, n, budget)`, else 1; a window whose coarsest bands cost
        more than the budget is matched in those, or not at all if `strict` (an empty array, None,
        0, 0). With k > 1 the window's rows v0, v1 and the disparity map's are on the grid of k-row
        bands from the image's top (`_bands`)."""
        gl, gr = self._check(left, right)
        win = self.window(box2d)
        if win is None:
            return np.zeros((0, 0), np.float32), None, 1, 0
        n = self.num_disparities if n is None else int(n)
        k = self.rows_for(win, n, budget) if binned else 1
        if k == 0:
            if strict:
                return np.zeros((0, 0), np.float32), None, 0, 0
            k = MAX_COST_BAND_ROWS
        u0, u1, v0, v1 = win
        if k > 1:
            v0, v1 = self._bands(win, k)
            if v1 <= v0:
                return np.zeros((0, 0), np.float32), None, 1, 0
        c0, c1 = self._columns(win, n)
        pad = n - (u0 - c0)     # > 0 only at the image's left border
        if k > 1:
            size = (c1 - c0, v1 - v0)
            cl = cv2.resize(gl[v0 * k:v1 * k, c0:c1], size, interpolation=cv2.INTER_AREA)
            cr = cv2.resize(gr[v0 * k:v1 * k, c0:c1], size, interpolation=cv2.INTER_AREA)
        else:
            cl, cr = np.ascontiguousarray(gl[v0:v1, c0:c1]), np.ascontiguousarray(gr[v0:v1, c0:c1])
        d = self._disparity(cl, cr, pad=pad, n=n, rows=k)
        return d[:, u0 - c0:u1 - c0], (u0, u1, v0, v1), k, self.binned_cost(win, n, k)

    def depth_window(self, left: np.ndarray, right: np.ndarray, box2d,
                     n: int | None = None) -> tuple[np.ndarray, tuple | None]:
        """Depth of the window around `box2d` only: ((v1-v0, u1-u0) float64 z, 0 = none,
        (u0, u1, v0, v1)); an empty or invalid box gives an empty array and None. n: the
        disparities [0, n) searched (`disparities_to`), default the full range."""
        d, win, _, _ = self._window_disparity(left, right, box2d, n)
        return (np.zeros((0, 0)), None) if win is None else (self._to_depth(d), win)

    def points_window(self, left: np.ndarray, right: np.ndarray, box2d, n: int | None = None) -> np.ndarray:
        """(N, 3) float32 cloud (left frame) of the window around `box2d` (n: as depth_window),
        matched with rows averaged if the window has more than `max_match_px` pixels or costs more than
        `max_match_cost` (`rows_for`; a window whose coarsest bands cost more is matched in those)."""
        return self._cloud(left, right, box2d, n)[0]

    def _cloud(self, left: np.ndarray, right: np.ndarray, box2d, n: int | None,
               budget: int | None = None, strict: bool = False) -> tuple[np.ndarray, int, int]:
        """(points_window's cloud, the pixels of the grid it was matched on, what the matching cost
        (`binned_cost`); pixels -1: `strict` and the window does not fit `budget` (`rows_for`),
        nothing matched). Converted where there is a
        disparity only (the window's depth map, built whole first, cost 1.3 ms of a 256 x 180
        body's 8.4 ms window, measured alone on one core)."""
        d, win, k, cost = self._window_disparity(left, right, box2d, n, binned=True, budget=budget,
                                                 strict=strict)
        if win is None:
            return np.zeros((0, 3), np.float32), (-1 if k == 0 else 0), 0
        u0, _, v0, _ = win
        vv, uu = np.nonzero(d > 0)
        zz = self.fb / d[vv, uu].astype(np.float64)    # as _to_depth: the same z, bit for bit
        c = self.camera
        out = np.empty((len(zz), 3), np.float32)
        out[:, 0] = (uu + u0 + 0.5 - c.cx) / c.fx * zz
        if k == 1:
            out[:, 1] = (vv + v0 + 0.5 - c.cy) / c.fy * zz
        else:    # a band's centre row in the camera's pixels
            out[:, 1] = (k * (vv + v0 + 0.5) - c.cy) / c.fy * zz
        out[:, 2] = zz
        return out, d.size, cost


# StereoCloud's depth following: the depths of the last window are its returns' FOLLOW_QUANTILE
# and 1 - FOLLOW_QUANTILE quantiles (a few stray matches do not set the range); a window with
# fewer than FOLLOW_MIN_POINTS returns says nothing (the next one searches the full range). A
# followed search that finds fewer returns per pixel of its window than FOLLOW_MIN_SHARE of the
# last window's is repeated over the full range: a body nearer than the search reaches does not
# leave holes only, SGBM matches much of its texture at wrong disparities inside the search (a
# sphere at 7-9 m searched down to 26 m: 19,000 returns at 22-60 m instead of 89,000 at 7-9 m).
FOLLOW_QUANTILE = 0.02
FOLLOW_MIN_POINTS = 64
FOLLOW_MIN_SHARE = 0.7


class StereoCloud:
    """Point clouds of the tracked region from a stereo pair, for `Track3D.update(image, points)`.

        cloud = StereoCloud(camera)
        out = track.update(left, cloud.bind(left, right))   # disparity only around the 2D box

    One StereoCloud per tracked body: it follows the body's depth (`StereoParams.follow_depth`),
    searching only the disparities of the depths the body can be at after the last window (the
    full range from `z_min_m` at the start, after `reset()`, and whenever the followed search
    finds too little). Its state is `depth_range` (`get_state` / `set_state`: checkpoint it with
    the Track3D's so that a restored loop matches as the uninterrupted one would).

    With `max_match_cost` set, the cap is each update's budget, the full-range retry's included
    (`StereoMatcher.rows_for`); `last_cost` is what an update matched, `last_dropped` whether its
    followed search was not trusted and the budget left too little to search again (no cloud)."""

    def __init__(self, camera: Camera, params: StereoParams | None = None, **overrides):
        self.matcher = StereoMatcher(camera, params, **overrides)
        self.depth_range: tuple[float, float] | None = None   # the last window's body depths (m)
        self.density: float | None = None    # the last window's returns per pixel
        self.last_disparities: int = self.matcher.num_disparities   # [0, n) searched by the last call
        self.last_cost: int = 0   # what the last call matched: its windows' `binned_cost`,
                                  # a retry's included
        self.last_dropped: bool = False   # the last call's retry did not fit the budget: no cloud

    def reset(self) -> None:
        """Forget the body's depth: the next window searches the full range (a new body)."""
        self.depth_range, self.density = None, None

    def get_state(self) -> dict:
        return {"depth_range": None if self.depth_range is None else [float(v) for v in self.depth_range],
                "density": self.density}

    def set_state(self, state: dict) -> None:
        """Restore a `get_state()`; a damaged one raises ValueError and changes nothing."""
        if not isinstance(state, dict):
            raise ValueError(f"damaged StereoCloud state: {state!r:.80}")
        r, dens = state.get("depth_range"), state.get("density")
        try:
            r = None if r is None else tuple(float(v) for v in r)
            dens = None if dens is None else float(dens)
        except (TypeError, ValueError):
            raise ValueError(f"damaged StereoCloud state: {state!r:.80}") from None
        if r is not None and (len(r) != 2 or not (np.isfinite(r[0]) and np.isfinite(r[1]) and 0.0 < r[0] <= r[1])):
            raise ValueError(f"damaged StereoCloud state: depth_range {state.get('depth_range')!r}")
        if dens is not None and not (np.isfinite(dens) and 0.0 <= dens <= 1.0):
            raise ValueError(f"damaged StereoCloud state: density {state.get('density')!r}")
        self.depth_range, self.density = r, dens

    def _search(self) -> int:
        k = float(self.matcher.params.follow_depth)
        if k == 0.0 or self.depth_range is None:
            return self.matcher.num_disparities
        return self.matcher.disparities_to(self.depth_range[0] / k)

    def _points(self, gl: np.ndarray, gr: np.ndarray, box2d, n: int, budget: int | None = None,
                strict: bool = False) -> tuple[np.ndarray, float, bool]:
        """(the window's cloud, its returns per pixel of the grid it was matched on, whether it was
        matched: False when `strict` and the window does not fit `budget`)."""
        pts, area, cost = self.matcher._cloud(gl, gr, box2d, n, budget, strict)
        if area < 0:
            return pts, 0.0, False
        self.last_cost += cost
        return pts, (len(pts) / area if area else 0.0), True

    def bind(self, left: np.ndarray, right: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A callable box2d -> (N, 3) float32 cloud of this pair around the box."""
        gl, gr = self.matcher._check(left, right)

        def points(box2d) -> np.ndarray:
            self.last_cost, self.last_dropped = 0, False
            budget = self.matcher.params.max_match_cost or None
            n = self._search()
            pts, density, _ = self._points(gl, gr, box2d, n, budget)
            if n < self.matcher.num_disparities and (len(pts) < FOLLOW_MIN_POINTS or self.density is None
                                                     or density < FOLLOW_MIN_SHARE * self.density):
                n = self.matcher.num_disparities
                left = None if budget is None else budget - self.last_cost
                # the followed cloud is not trusted (a nearer body's texture matched at wrong
                # depths): no cloud rather than it when the retry does not fit what is left
                pts, density, matched = self._points(gl, gr, box2d, n, left, strict=True)
                self.last_dropped = not matched
            self.last_disparities = n
            if self.matcher.params.follow_depth > 0.0:
                if len(pts) >= FOLLOW_MIN_POINTS:
                    lo, hi = np.quantile(pts[:, 2], [FOLLOW_QUANTILE, 1.0 - FOLLOW_QUANTILE])
                    self.depth_range, self.density = (float(lo), float(hi)), density
                else:
                    self.reset()
            return pts
        return points
