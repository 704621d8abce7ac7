"""The body's past views carried into this frame: a back face no single view can see (issue 12).

One frame shows the body's near side only; A3BoxNet guesses the far side from the shape of the
near one, and on bodies unlike its training shapes that guess is the largest error left (the
hidden depth). The body turns while the loop watches it, so the side hidden now was in view
before. `BodyViews` keeps the past views in a frame fixed to the body:

- every `every`-th frame with returns (a key frame), its returns are binned into a grid of at most
  `cells` x `cells` cells over the 2D box (the mean point of each cell: a cloud of any sensor
  and any density gives the same small surface);
- the grid's points are registered onto the last key frame's grid by point-to-plane ICP with
  projective matching (each point paired with the cell it projects into: no search, linear in
  the points), started from the last turn and the shift that puts the two grids' centroids
  together; the motions chained give the body frame;
- a registration that leaves fewer than `min_fit` of the points within `good_m` of the other
  surface (the body left the view, spun too far, a noisy sensor) starts the views over, so one
  wrong pose is never carried on;
- `far` is the farthest point of the views in this frame's camera frame: the back face is at
  least there;
- `limit` is the farthest a body point can be along this frame's lines of sight through its
  outline (space carving): every past view from another direction saw empty sky outside its
  outline and empty space in front of its surface, so a point of the body is inside each view's
  outline and not in front of what it saw. A few views from directions at least `carve_angle_deg`
  apart are kept for it (`carve_views`); the back face is at most there (never nearer than `far`);
- `extent` is the views' extent in the last key frame's camera frame, once a key frame that saw
  the body whole is among them: a body cut by the image border keeps it across the view (the
  body turns, so the last whole view's extent goes stale).

Its ceiling was measured with the simulator's pose (benchmarks/bench_accumulation.py,
docs/models.md); in the loop (docs/runtime.md, README "Long watches") over 300 frames the views'
farthest point lifts the single-frame box most on held-out shapes; over 60 frames it hardly
matters.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .state import damaged, read_array, read_flag, read_float, read_int

# a registration stops at a step below 0.006 degrees and 0.1 mm: far below what the back face
# needs (cm)
DONE_RAD, DONE_M = 1e-4, 1e-4
GRID_POINTS_PER_CELL = 4    # surface_grid bins at most this many points per cell on average

__all__ = ["BodyViewsParams", "BodyViews", "SurfaceGrid", "surface_grid", "grid_normals", "point_to_plane",
           "projective_fit", "carved_back", "hold_back_face"]


# Upper bounds of the settings whose cost grows each frame or whose points ride in the state: a
# carve_views of 100,000 grew the state by 16 KB a frame (32 MB after 2,000 frames, get_state 0.7 s;
# a latency walkthrough)
CARVE_VIEWS_MAX = 64
_HIGH = {"carve_views": CARVE_VIEWS_MAX, "max_points": 200_000, "view_points": 20_000, "carve_rays": 4096,
         "carve_samples": 1024}


@dataclass(frozen=True)
class BodyViewsParams:
    """How `BodyViews` samples, registers and keeps views."""
    every: int = 3              # a key frame every N frames with returns (registration and a new view)
    cells: int = 48             # the surface grid: at most cells x cells over the 2D box
    iters: int = 6              # ICP steps per registration (from the start below, 4 did as well as 12)
    icp_points: int = 500       # grid points registered (a stride of them)
    max_dist_m: float = 1.0     # ICP: pairs farther apart than this are left out
    good_m: float = 0.03        # a point this close to the other surface (along its normal) fits
    min_fit: float = 0.6        # a registration fitting fewer of the points starts the views over
    view_points: int = 400      # points of each view kept in the body frame
    max_points: int = 8000      # view points kept (every other one dropped past it)
    carve_views: int = 12       # views kept for the carved limit of the back face (0: no carving; at
                                # most CARVE_VIEWS_MAX: each is carved every frame and rides in the state)
    carve_angle_deg: float = 10.0   # a view is kept when this far from every kept one
    carve_rays: int = 64        # lines of sight through this view's outline carved
    carve_samples: int = 24     # samples along each, front to carve_reach x the body's width behind
    carve_reach: float = 2.0
    carve_tol_m: float = 0.05   # a sample this much in front of a view's surface is still kept
    cut_extent: int = 2         # a body cut by the image border takes its extent on the first N axes
                                # (x, y, z) from the views that saw it whole (0: the last whole box's)

    def __post_init__(self) -> None:
        for name in ("every", "cells", "iters", "icp_points", "view_points", "max_points", "carve_views",
                     "carve_rays", "carve_samples", "cut_extent"):
            v = getattr(self, name)
            low = 0 if name in ("carve_views", "cut_extent") else 1
            high = _HIGH.get(name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low or (high and v > high):
                raise ValueError(f"BodyViewsParams.{name} must be an integer >= {low}"
                                 + (f" and <= {high}" if high else "") + f", got {v!r}")
        for name in ("max_dist_m", "good_m", "carve_reach", "carve_tol_m"):
            v = getattr(self, name)
            if not (np.isfinite(float(v)) and float(v) > 0.0):
                raise ValueError(f"BodyViewsParams.{name} must be a positive number of metres, got {v!r}")
        if not 0.0 < float(self.min_fit) <= 1.0:
            raise ValueError(f"BodyViewsParams.min_fit must be in (0, 1], got {self.min_fit!r}")
        if not 0.0 <= float(self.carve_angle_deg) < 180.0:
            raise ValueError(f"BodyViewsParams.carve_angle_deg must be in [0, 180), got {self.carve_angle_deg!r}")
        if self.cut_extent > 3:
            raise ValueError(f"BodyViewsParams.cut_extent must be 0-3 axes, got {self.cut_extent!r}")


@dataclass
class SurfaceGrid:
    """A surface seen from the camera, binned over a 2D box: cell (row, col) holds the mean of the
    points projecting into pixels [x0 + col * step, x0 + (col + 1) * step) x [y0 + row * step, ...).

    points (rows, cols, 3) float64, normals (rows, cols, 3) float64 unit (where `normal_ok`),
    valid (rows, cols) bool: the cell holds points; normal_ok: it and its four neighbours do;
    near (rows, cols) float64: the least z of the cell's points (inf where none; None: the
    points' z, a grid made elsewhere)."""
    points: np.ndarray
    normals: np.ndarray
    valid: np.ndarray
    normal_ok: np.ndarray
    x0: float
    y0: float
    step: float
    near: np.ndarray | None = None

    def near_z(self) -> np.ndarray:
        """(rows, cols) the least z seen in each cell, inf where empty."""
        if self.near is not None:
            return self.near
        return np.where(self.valid, self.points[..., 2], np.inf)

    def cells_of(self, camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col) int64 of the cell each point (n, 3) projects into, and whether it is in the grid."""
        z = points[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):   # camera.project, without its copies
            c = np.floor((camera.fx * points[:, 0] / z + (camera.cx - self.x0)) / self.step)
            r = np.floor((camera.fy * points[:, 1] / z + (camera.cy - self.y0)) / self.step)
        rows, cols = self.valid.shape
        inside = (points[:, 2] > 0) & (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
        r = np.where(inside, r, 0).astype(np.int64)
        c = np.where(inside, c, 0).astype(np.int64)
        return r, c, inside


def surface_grid(camera: Camera, points: np.ndarray, box2d: np.ndarray, cells: int = 48) -> SurfaceGrid:
    """Bin the points (n, 3) projecting into box2d [x, y, w, h] into at most cells x cells square
    cells (mean point each) with normals from the neighbouring cells' central differences."""
    x, y, w, h = (float(v) for v in box2d)
    step = max(1.0, max(w, h) / cells)
    cols, rows = max(int(np.ceil(w / step)), 1), max(int(np.ceil(h / step)), 1)
    grid = SurfaceGrid(np.zeros((rows, cols, 3)), np.zeros((rows, cols, 3)), np.zeros((rows, cols), bool),
                       np.zeros((rows, cols), bool), x, y, step)
    p = np.asarray(points).reshape(-1, 3)
    most = GRID_POINTS_PER_CELL * cells * cells
    if len(p) > most:   # a near body's 100,000 returns: a stride of them fills the cells as well
        p = p[:: int(np.ceil(len(p) / most))]
    p = p.astype(np.float64)
    r, c, inside = grid.cells_of(camera, p)
    lin = (r * cols + c)[inside]
    p = p[inside]
    n = np.bincount(lin, minlength=rows * cols).astype(np.float64)
    for k in range(3):
        grid.points[..., k] = (np.bincount(lin, weights=p[:, k], minlength=rows * cols)
                               / np.maximum(n, 1.0)).reshape(rows, cols)
    grid.valid[:] = (n > 0).reshape(rows, cols)
    near = np.full(rows * cols, np.inf)
    np.minimum.at(near, lin, p[:, 2])
    grid.near = near.reshape(rows, cols)
    grid.normals, grid.normal_ok = grid_normals(grid.points, grid.valid)
    return grid


def grid_normals(points: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A grid's (rows, cols, 3) unit normals from the neighbouring cells' central differences and
    (rows, cols) bool where they hold (the cell and its four neighbours have points). The one
    formula for `surface_grid` and for a checkpoint's grid, which keeps the points only: the two
    give the same bits."""
    rows, cols = valid.shape
    normals, normal_ok = np.zeros((rows, cols, 3)), np.zeros((rows, cols), bool)
    P, ok = points, valid
    if rows >= 3 and cols >= 3:
        du = P[1:-1, 2:] - P[1:-1, :-2]
        dv = P[2:, 1:-1] - P[:-2, 1:-1]
        nrm = np.cross(du, dv)
        length = np.linalg.norm(nrm, axis=-1)
        good = ok[1:-1, 1:-1] & ok[1:-1, 2:] & ok[1:-1, :-2] & ok[2:, 1:-1] & ok[:-2, 1:-1] & (length > 0)
        normals[1:-1, 1:-1] = nrm / np.where(length > 0, length, 1.0)[..., None]
        normal_ok[1:-1, 1:-1] = good
    return normals, normal_ok


def point_to_plane(src: np.ndarray, match, init: np.ndarray, iters: int, good_m: float,
                   done_rad: float = 1e-6, done_m: float = 1e-5) -> tuple[np.ndarray, float]:
    """Gauss-Newton point-to-plane ICP from the rigid transform `init` (4, 4); match(points (n, 3))
    -> (kept mask (n,), their surface points (k, 3), their unit normals (k, 3)). Stops after
    `iters` steps or a step below done_rad and done_m. Returns the
    transform (4, 4) that puts src (n, 3) onto the surface and the share of src (0..1) within
    good_m of it along the normal with it."""
    M = np.array(init, dtype=np.float64)
    for _ in range(iters):
        s = src @ M[:3, :3].T + M[:3, 3]
        keep, q, n = match(s)
        if keep.sum() < 6:
            break
        s = s[keep]
        A = np.empty((len(s), 6))                                 # d(n . (R s + t - q)) / d(w, t)
        A[:, 0] = s[:, 1] * n[:, 2] - s[:, 2] * n[:, 1]           # s x n
        A[:, 1] = s[:, 2] * n[:, 0] - s[:, 0] * n[:, 2]
        A[:, 2] = s[:, 0] * n[:, 1] - s[:, 1] * n[:, 0]
        A[:, 3:] = n
        r = np.einsum("ij,ij->i", n, q - s)
        # the normal equations, damped a little: a surface that leaves a motion free (a plane
        # sliding in itself) gets the smallest step there, not an arbitrary one
        H = A.T @ A
        x = np.linalg.solve(H + np.eye(6) * (1e-9 * np.trace(H) + 1e-12), A.T @ r)
        w, t = x[:3], x[3:]
        theta = float(np.linalg.norm(w))
        K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        dR = np.eye(3) + (np.sin(theta) / theta * K + (1 - np.cos(theta)) / theta ** 2 * K @ K if theta > 1e-12 else K)
        step = np.eye(4)
        step[:3, :3], step[:3, 3] = dR, t
        M = step @ M
        if theta < done_rad and np.linalg.norm(t) < done_m:
            break
    s = src @ M[:3, :3].T + M[:3, 3]
    keep, q, n = match(s)
    resid = np.abs(np.einsum("ij,ij->i", n, s[keep] - q))
    return M, float((resid < good_m).sum() / max(len(src), 1))


def projective_fit(src: np.ndarray, grid: SurfaceGrid, camera: Camera, init: np.ndarray, iters: int = 6,
                   max_dist_m: float = 1.0, good_m: float = 0.03, done_rad: float = DONE_RAD,
                   done_m: float = DONE_M) -> tuple[np.ndarray, float]:
    """`point_to_plane` with each point matched to the grid cell (with a normal) it projects into."""
    cols = grid.valid.shape[1]
    points, normals, ok = grid.points.reshape(-1, 3), grid.normals.reshape(-1, 3), grid.normal_ok.reshape(-1)
    max_d2 = max_dist_m * max_dist_m

    def match(s):
        r, c, keep = grid.cells_of(camera, s)
        lin = r * cols + c
        keep &= ok[lin]
        idx = np.flatnonzero(keep)
        q = points[lin[idx]]
        d = q - s[idx]
        near = np.einsum("ij,ij->i", d, d) < max_d2
        keep[idx[~near]] = False
        idx = lin[idx[near]]
        return keep, points[idx], normals[idx]

    return point_to_plane(src, match, init, iters, good_m, done_rad, done_m)


def hold_back_face(box: np.ndarray, far: float | None, limit: float | None) -> np.ndarray:
    """box [cx, cy, cz, w, h, d] (camera frame, z the depth) with its back face at least at `far`
    and at most at `limit` (either None: no bound), front face kept; where the two cross, `far`
    wins (the views saw that far). A bound at or in front of the front face leaves the box as it is."""
    front, back = box[2] - box[5] / 2.0, box[2] + box[5] / 2.0
    lo = -np.inf if far is None else float(far)
    hi = np.inf if limit is None else max(float(limit), lo)
    new = min(max(back, lo), hi)
    if new == back or not new > front:
        return box
    out = np.array(box, dtype=np.float64)
    out[5] = new - front
    out[2] = front + out[5] / 2.0
    return out


def carved_back(camera: Camera, grid: SurfaceGrid, G: np.ndarray, past: list[tuple[SurfaceGrid, np.ndarray]],
                rays: int = 64, samples: int = 24, reach: float = 2.0, tol_m: float = 0.05) -> float:
    """The farthest depth (z of `grid`'s camera, metres) a point of the body can have along the
    lines of sight through `grid`'s outline, given past views `past` [(grid, body -> that camera
    (4, 4))] and this view's camera -> body `G` (4, 4): space carving on at most `rays` lines of
    sight (cell centres), `samples` points each from the nearest return to `reach` x the
    returns' width behind the farthest. A point survives a past view when it projects outside
    that view's image (unseen there) or into a cell of its grid with returns and no nearer than
    their least z - tol_m (a grid spans the body's outline and a margin: off it is sky); a point
    in front of this view's own surface is empty. inf without a past view or where a point at
    the last sample survives; never nearer than the farthest return of the rays."""
    if not past:
        return float("inf")
    rows, cols = grid.valid.shape
    idx = np.flatnonzero(grid.valid)
    idx = idx[:: max(1, int(np.ceil(len(idx) / rays)))]
    near = grid.near_z().reshape(-1)[idx]
    u = grid.x0 + (idx % cols + 0.5) * grid.step
    v = grid.y0 + (idx // cols + 0.5) * grid.step
    d = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(len(idx))], axis=1)
    seen = grid.points[grid.valid]
    width = max(float(np.ptp(seen[:, 0])), float(np.ptp(seen[:, 1])), 0.05)
    front = float(near.min())
    z = np.linspace(front, float(near.max()) + reach * width, samples)
    ray, k = np.nonzero(z[None, :] >= near[:, None])     # behind this view's own surface
    zs = z[k]
    pts = d[ray] * zs[:, None]
    body = pts @ G[:3, :3].T + G[:3, 3]
    fx, fy, cx, cy, W, Hh = camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height
    for g, H in past:
        if len(zs) == 0:
            break
        q = body @ H[:3, :3].T + H[:3, 3]
        qz = q[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = fx * q[:, 0] / qz + cx
            v = fy * q[:, 1] / qz + cy
        in_view = (qz > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < Hh)
        gr, gc = g.valid.shape
        c = np.floor((u - g.x0) / g.step)
        r = np.floor((v - g.y0) / g.step)
        on = in_view & (c >= 0) & (c < gc) & (r >= 0) & (r < gr)
        lin = np.where(on, r * gc + c, 0).astype(np.int64)
        # in that view but off its grid: sky (the grid spans the body's outline and a margin)
        keep = ~in_view | (on & (qz >= g.near_z().reshape(-1)[lin] - tol_m))
        body, zs = body[keep], zs[keep]
    if len(zs) and zs.max() >= z[-1]:   # alive at the last sample: the views do not bound it
        return float("inf")
    return float(max(near.max(), zs.max() if len(zs) else -np.inf))


class BodyViews:
    """Past views of one body in a body-fixed frame, registered from the depth alone (module doc).

    update(points, box2d) each frame with an estimate; reset() when the tracker starts on a new
    target (a lost target keeps its views: the fit test decides when it is found again)."""

    def __init__(self, camera: Camera, params: BodyViewsParams | None = None):
        self.camera = camera
        self.params = params or BodyViewsParams()
        self.reset()

    def reset(self) -> None:
        self._frames = 0                 # frames with returns since the last reset
        self._G = np.eye(4)              # the last key frame's camera frame -> the body frame
        self._motion = np.eye(4)         # the last key-frame-to-key-frame motion (new -> old)
        self._grid: SurfaceGrid | None = None
        self._centroid = np.zeros(3)     # the last key frame's grid points' mean
        self._body = np.zeros((0, 3))    # the views, body frame
        self._offset = float("nan")      # far minus the returns' nearest depth at the last key frame
        self._pending: tuple | None = None   # a key frame's (grid, returns kept, front, carve), registered next call
        self._carve_job: tuple | None = None  # a registered key frame's (grid, G, front), carved next call
        self._carved: list[tuple[SurfaceGrid, np.ndarray]] = []   # views kept for carving: (grid, camera -> body)
        self._limit = float("inf")       # the carved limit minus the returns' nearest depth at its key frame
        self.limit: float | None = None  # this frame's carved limit of the back face (z, m), or None
        self._whole = False              # a registered key frame of these views saw the body whole
        self._extent = np.full(3, np.nan)   # the views' extent in the last key frame's camera frame
        self.extent: np.ndarray | None = None   # (3,) this frame's, when the views hold a whole view
        self.restarts = 0                # registrations that started the views over
        self.views = 0                   # views in the body frame

    def update(self, points: np.ndarray, box2d: np.ndarray, front: float | None = None,
               carve: bool = True, whole: bool = False) -> float | None:
        """This frame's returns (n, 3) (the frustum: camera frame) and 2D box [x, y, w, h] -> the
        farthest depth (m, this frame's z) a past view saw of the body, or None (no registered
        view but one): the last registered key frame's far side, held at the same distance behind
        the returns' nearest point (`front`, their least z, when the caller has it). carve=False:
        this view's outline is not the body's (its returns stop at the sensor's range), so it is
        registered and kept but neither carves nor is bounded by carving (`limit` None until the
        next key frame that carves). whole: this view saw the body whole (off the image border,
        within the sensor's range); once one such key frame is registered, `extent` is the views'
        extent (x, y, z; m) in the last key frame's camera frame, else None.

        A key frame's grid is made in its own call and registered in the next one: the two
        halves of the work land in different frames (the loop's worst frame ~0.6 ms shorter)."""
        pts = np.asarray(points).reshape(-1, 3)
        self.limit = self.extent = None
        if len(pts) == 0:
            return None
        front = float(pts[:, 2].min()) if front is None else float(front)
        if self._carve_job is not None:
            self._carve(*self._carve_job)
            self._carve_job = None
        if self._pending is not None:
            self._register(*self._pending)
            self._pending = None
        key = self._frames % self.params.every == 0
        self._frames += 1
        if key:
            p = self.params
            grid = surface_grid(self.camera, pts, box2d, p.cells)
            if grid.valid.sum() >= 6:
                keep = pts[:: max(1, int(np.ceil(len(pts) / p.view_points)))].astype(np.float64)
                self._pending = (grid, keep, front, bool(carve), bool(whole))
        if np.isfinite(self._limit):
            self.limit = front + self._limit
        if np.all(np.isfinite(self._extent)):
            self.extent = self._extent.copy()
        return front + self._offset if np.isfinite(self._offset) else None

    def past_points(self, points: np.ndarray) -> np.ndarray | None:
        """The views' points (m, 3) float32 in this frame's camera frame, or None (fewer than two
        registered views): the body frame seen from the last registered key frame, moved by the
        shift of the returns' mean since then (this frame's `points` (n, 3) against that key
        frame's grid; the turn since it, at most `every` frames, is left out). Call after this
        frame's `update`. Points the body turned out of view are among them: a box network given
        them sees part of the side hidden now (track3d.boxnet, models with ``past_views``)."""
        pts = np.asarray(points).reshape(-1, 3)
        if self.views < 2 or len(self._body) == 0 or len(pts) == 0:
            return None
        inv = np.linalg.inv(self._G)
        # einsum: the column sums of a near body's 40,000 returns in 0.13 ms (mean(axis=0) 0.48 ms)
        mean = np.einsum("ij->j", pts, dtype=np.float64) / len(pts)
        shift = inv[:3, 3] + (mean - self._centroid)
        return (self._body @ inv[:3, :3].T + shift).astype(np.float32)

    def _carve(self, grid: SurfaceGrid, G: np.ndarray, front: float) -> None:
        """The carved limit of a registered key frame (`carved_back` against the kept views from
        other directions); the frame joins the kept views when none is within carve_angle_deg of
        it (the oldest dropped past carve_views)."""
        p = self.params
        centre = self._body.mean(axis=0) if len(self._body) else np.zeros(3)

        def look(Gk: np.ndarray) -> np.ndarray:   # the unit direction from the body to that camera
            v = Gk[:3, 3] - centre
            return v / max(float(np.linalg.norm(v)), 1e-12)

        here = look(G)
        cos = np.cos(np.radians(p.carve_angle_deg))
        looks = [look(Gk) for _, Gk in self._carved]
        far_first = np.argsort([float(here @ lk) for lk in looks])     # the most different first
        past = [(self._carved[i][0], np.linalg.inv(self._carved[i][1])) for i in far_first
                if float(here @ looks[i]) < cos]
        bound = carved_back(self.camera, grid, G, past, p.carve_rays, p.carve_samples, p.carve_reach,
                            p.carve_tol_m)
        self._limit = bound - front
        if len(past) == len(looks):   # a new direction: kept (the oldest dropped past carve_views)
            self._carved.append((grid, G.copy()))
            if len(self._carved) > p.carve_views:
                del self._carved[0]

    def _register(self, grid: SurfaceGrid, keep: np.ndarray, front: float, carve: bool = True,
                  whole: bool = False) -> None:
        """Register a key frame's grid onto the last one's, add its returns `keep` to the views,
        and set the far side's distance behind its nearest return `front` and, once a whole view
        is among them, the views' extent."""
        p = self.params
        view = grid.points[grid.valid]
        fit = 0.0
        if self._grid is not None:
            src = view[:: max(1, int(np.ceil(len(view) / p.icp_points)))]
            # the last turn, and the shift that puts this view's centroid on the last one's: a
            # fast body moves metres between frames, its turn changes slowly (a second try from
            # rest when the fit fails changed nothing on the seed-11 set: not made)
            init = self._motion.copy()
            init[:3, 3] = self._centroid - init[:3, :3] @ view.mean(axis=0)
            M, fit = projective_fit(src, self._grid, self.camera, init, p.iters, p.max_dist_m, p.good_m)
        if fit >= p.min_fit:
            self._motion = M
            self._G = self._G @ M
        else:   # the first view, or a registration gone wrong: a new body frame
            if self._grid is not None:
                self.restarts += 1
            # the last good motion stays the next start: a fast spin goes on turning as it did
            self._G, self._body, self.views = np.eye(4), np.zeros((0, 3)), 0
            self._G[:3, 3] = -view.mean(axis=0)
            self._carved, self._limit = [], float("inf")
            self._whole, self._extent = False, np.full(3, np.nan)
        self._whole = self._whole or bool(whole)
        self._grid, self._centroid = grid, view.mean(axis=0)
        self._body = np.concatenate([self._body, keep @ self._G[:3, :3].T + self._G[:3, 3]])
        if len(self._body) > p.max_points:   # thinned over every view: the oldest saw the side hidden now
            self._body = self._body[::2]
        self.views += 1
        if self.params.carve_views > 0 and carve:
            self._carve_job = (grid, self._G.copy(), front)
        elif not carve:   # a view that is no outline (the sensor's range cut it) neither carves nor bounds
            self._limit = float("inf")
        if self.views < 2:
            self._offset = float("nan")
            return
        inv = np.linalg.inv(self._G)
        # one axis at a time: a (n, 3) product and its column reductions cost ten times as much
        z = self._body @ inv[2, :3] + inv[2, 3]
        self._offset = float(z.max()) - front
        if self._whole:
            x, y = (self._body @ inv[k, :3] + inv[k, 3] for k in (0, 1))
            self._extent = np.array([x.max() - x.min(), y.max() - y.min(), z.max() - z.min()])

    def get_state(self) -> dict:
        """Plain data (arrays and builtins) for `set_state`. Each grid is one record of ``grids``
        (`grid_record`), which the views' fields name by its index: the last key frame's grid is
        also the carving job's and often a carving view's."""
        grids, index = [], {}

        def ref(g):
            if g is None:
                return None
            if id(g) not in index:
                index[id(g)] = len(grids)
                grids.append(grid_record(g))
            return index[id(g)]

        pend, job = self._pending, self._carve_job
        return {"frames": self._frames, "G": self._G.copy(), "motion": self._motion.copy(),
                "body": self._body.copy(), "offset": self._offset, "centroid": self._centroid.copy(),
                "restarts": self.restarts, "views": self.views, "grid": ref(self._grid),
                "pending": None if pend is None else {"grid": ref(pend[0]), "keep": pend[1].copy(),
                                                      "front": pend[2], "carve": pend[3], "whole": pend[4]},
                "limit": self._limit, "whole": self._whole,
                "extent": None if not np.all(np.isfinite(self._extent)) else self._extent.copy(),
                "carve_job": None if job is None else {"grid": ref(job[0]), "G": job[1].copy(), "front": job[2]},
                "carved": [{"grid": ref(g), "G": Gk.copy()} for g, Gk in self._carved],
                "grids": grids}

    def set_state(self, st: dict) -> None:
        """Restore a `get_state()` (or one written before the compact grids, each grid a dense
        record in place); a damaged one raises ValueError (one line) and changes nothing."""
        def transform(x, what):
            return read_array(x, what, (4, 4))

        with damaged("body views"):
            records = st.get("grids", [])
            if not isinstance(records, list):
                raise ValueError(f"grids must be a list, got {type(records).__name__}")
            shared = [read_grid(g) for g in records]

            def grid_of(g):
                if g is None or isinstance(g, dict):
                    return None if g is None else read_grid(g)
                return shared[read_int(g, "grid index")]

            grid = grid_of(st["grid"])
            pend = st.get("pending")
            pending = None if pend is None else (
                grid_of(pend["grid"]), read_array(pend["keep"], "kept returns", (-1, 3)),
                read_float(pend["front"], "pending front"), read_flag(pend.get("carve", True), "carve"),
                read_flag(pend.get("whole", False), "whole"))
            G, motion = transform(st["G"], "G"), transform(st["motion"], "motion")
            body = read_array(st["body"], "body", (-1, 3))
            centroid = read_array(st["centroid"], "centroid", (3,))
            frames, restarts = read_int(st["frames"], "frames"), read_int(st["restarts"], "restarts")
            views, offset = read_int(st["views"], "views"), read_float(st["offset"], "offset", nan_ok=True)
            # a state from before the carving has none: the limit starts with the next key frame
            job = st.get("carve_job")
            limit = read_float(st.get("limit", float("inf")), "limit", nan_ok=True, inf_ok=True)
            carve_job = None if job is None else (grid_of(job["grid"]), transform(job["G"], "carving G"),
                                                  read_float(job["front"], "carving front"))
            carved = [(grid_of(c["grid"]), transform(c["G"], "carved G")) for c in st.get("carved", [])]
            # a state from before the views' extent has none: it starts with the next whole key frame
            whole = read_flag(st.get("whole", False), "whole")
            ext = st.get("extent")
            extent = np.full(3, np.nan) if ext is None else read_array(ext, "extent", (3,))
        self._frames, self._G, self._motion, self._body = frames, G, motion, body
        self._offset, self.restarts, self.views = offset, restarts, views
        self._grid, self._centroid, self._pending = grid, centroid, pending
        self._limit, self._carve_job, self._carved = limit, carve_job, carved
        self.limit = self.extent = None
        self._whole, self._extent = whole, extent


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal to the bit (-0.0 is not 0.0, a nan is itself): what a restored grid must be."""
    return a.dtype == b.dtype and a.shape == b.shape and np.ascontiguousarray(a).tobytes() == b.tobytes()


def grid_record(g: SurfaceGrid) -> dict:
    """A grid as plain data for a checkpoint, compact: which cells hold points (bits), their
    points and least depths. `surface_grid` makes the rest of those (empty cells' points 0.0 and
    depths inf, the normals by `grid_normals`), so `read_grid` gives every array back to the bit.
    A grid whose normals are not `grid_normals`' keeps them (and normal_ok) in the record; one
    whose empty cells hold anything else is kept dense, as states were before."""
    valid, points, near = g.valid, g.points, g.near_z()
    compact = (valid.dtype == bool and points.dtype == np.float64 and near.dtype == np.float64
               and valid.ndim == 2 and points.shape == (*valid.shape, 3) and near.shape == valid.shape)
    # a -0.0 would come back 0.0: the empty cells' bits must all be zero
    if not (compact and not points[~valid].view(np.uint64).any() and (near[~valid] == np.inf).all()
            and np.isfinite(near[valid]).all()):
        return {"points": points.copy(), "normals": g.normals.copy(), "valid": valid.copy(),
                "normal_ok": g.normal_ok.copy(), "x0": g.x0, "y0": g.y0, "step": g.step, "near": near.copy()}
    rows, cols = valid.shape
    rec = {"rows": rows, "cols": cols, "x0": g.x0, "y0": g.y0, "step": g.step,
           "cells": np.packbits(valid.reshape(-1)), "points": points[valid], "near": near[valid]}
    normals, normal_ok = grid_normals(points, valid)
    if not (_same_bits(g.normals, normals) and _same_bits(g.normal_ok, normal_ok)):
        rec["normals"], rec["normal_ok"] = g.normals.copy(), g.normal_ok.copy()
    return rec


def read_grid(g: dict) -> SurfaceGrid:
    """A `grid_record` back (or the dense record of states before it); ValueError if damaged."""
    if not isinstance(g, dict):
        raise ValueError(f"a grid must be a record, got {type(g).__name__}")
    x0, y0 = read_float(g["x0"], "grid x0"), read_float(g["y0"], "grid y0")
    step = read_float(g["step"], "grid step", lo=1.0)
    if "cells" not in g:
        points = read_array(g["points"], "grid points", (-1, -1, 3))
        rows, cols = points.shape[:2]
        if rows < 1 or cols < 1:
            raise ValueError(f"a grid of {rows} x {cols} cells")
        near = g.get("near")
        return SurfaceGrid(points, read_array(g["normals"], "grid normals", (rows, cols, 3)),
                           read_array(g["valid"], "grid cells", (rows, cols), bool),
                           read_array(g["normal_ok"], "grid normals' cells", (rows, cols), bool),
                           x0, y0, step, None if near is None else _read_near(near, rows, cols))
    rows, cols = read_int(g["rows"], "grid rows", 1), read_int(g["cols"], "grid cols", 1)
    bits = g["cells"]
    if not (isinstance(bits, np.ndarray) and bits.dtype == np.uint8 and bits.ndim == 1):
        raise ValueError("grid cells must be a uint8 array of bits")
    if len(bits) != -(-rows * cols // 8):   # before anything of rows x cols is made
        raise ValueError(f"grid cells: {len(bits)} bytes for {rows} x {cols} cells")
    every = np.unpackbits(bits)
    if every[rows * cols:].any():
        raise ValueError("grid cells: bits set past the last cell")
    valid = every[:rows * cols].astype(bool).reshape(rows, cols)
    k = int(valid.sum())
    held = read_array(g["points"], f"grid points of {k} cells", (k, 3))
    least = read_array(g["near"], f"grid depths of {k} cells", (k,))
    points, near = np.zeros((rows, cols, 3)), np.full((rows, cols), np.inf)
    points[valid], near[valid] = held, least
    if "normals" in g or "normal_ok" in g:
        normals = read_array(g["normals"], "grid normals", (rows, cols, 3))
        normal_ok = read_array(g["normal_ok"], "grid normals' cells", (rows, cols), bool)
    else:
        normals, normal_ok = grid_normals(points, valid)
    return SurfaceGrid(points, normals, valid, normal_ok, x0, y0, step, near)


def _read_near(x, rows: int, cols: int) -> np.ndarray:
    """A grid's least depths: finite, or inf where a cell is empty."""
    near = read_array(x, "grid depths", (rows, cols), finite=False)
    if np.isnan(near).any() or (near == -np.inf).any():
        raise ValueError("grid depths are nan or -inf")
    return near
