"""The body's outline in the image from the depth returns (range sensors against empty space).

A range sensor in space returns depth only where there is a body: the returns around the 2D
tracker's box, rasterised in the image, form the body's silhouette, dark side included. The 2D
tracker sees the lit body and drifts or shrinks to a part of it (a bilobate body turning its
second lobe into view: IoU_2d 0.66 on the accuracy set's sequence 0010 while the returns'
outline keeps 0.94). `silhouette_box` is the bounding box of the connected returns that overlap
the tracker's box, searched in that box grown by `grow` of its size on each side, and grown
again around the outline where the outline reaches the search region's edge (the body goes on
past a region the tracker's box set; REGROW_STEPS times at most).

The raster is coarse (cells of at least CELL_MIN_PX pixels, at most GRID_CELLS per side of the
search region) and closed by one cell, so that a sparse sensor's grid (a flash LiDAR's returns
every few pixels) still reads as one body; the box itself is the extent of the kept returns'
projections (pixel centres, half a pixel out on each side), not of the cells.
"""
from __future__ import annotations

import cv2
import numpy as np

from .frustum import extract_frustum

__all__ = ["CELL_MIN_PX", "GRID_CELLS", "MIN_CELLS", "MIN_SHARE", "RASTER_POINTS", "REGROW_STEPS", "silhouette_box",
           "find_body", "contain"]

CELL_MIN_PX = 2.5     # pixels: a cell spans at least this (gaps of a coarse sensor grid close)
GRID_CELLS = 96       # cells on the longer side of the search region at most (cost bound)
MIN_SHARE = 0.05      # a component is the body's when it holds this share of the box's occupied cells
RASTER_POINTS = 6000  # returns rasterised at most (every k-th of a larger search region's)
# Searches grown around the outline at most, where it reaches the search region's edge inside the
# image. The region is the tracker's box grown: a tracker that jumped off a large near body (a
# flash-LiDAR long watch's test 0005, EdgeTrack drawn to a galaxy band behind it, frames 278-291)
# overlapped only its top, and the outline stopped at the region's edge, 20-60 px short of the
# body's bottom (IoU_2d 0.6-0.85 where NanoTrack's kept 0.95). Each step costs one frustum cut
# and one raster; 3 cover a body several times the box's size.
REGROW_STEPS = 3
# An outline holds at least this many occupied cells: one or two are a depth sensor's false alarms
# (a lone return in the tracker's box of a body past the ToF range had become a 1 x 1 px box,
# reported and carried on; track3d.stray_returns), not a body's outline.
MIN_CELLS = 3


def _project(pts: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) float32 of points (n, 3) float32 under M (3, 4), column by column
    (a (n, 3) @ (3, 3) product costs numpy several times more); the camera frame's M (no
    rotation, no translation) needs two products a coordinate."""
    m = np.asarray(M, dtype=np.float64)
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    f = np.float32
    if m[0, 1] == m[1, 0] == m[2, 0] == m[2, 1] == m[2, 3] == 0.0 and m[2, 2] == 1.0 and m[0, 3] == m[1, 3] == 0.0:
        iz = f(1.0) / z
        return x * iz * f(m[0, 0]) + f(m[0, 2]), y * iz * f(m[1, 1]) + f(m[1, 2])
    w = f(m[2, 0]) * x + f(m[2, 1]) * y + f(m[2, 2]) * z + f(m[2, 3])
    return ((f(m[0, 0]) * x + f(m[0, 1]) * y + f(m[0, 2]) * z + f(m[0, 3])) / w,
            (f(m[1, 0]) * x + f(m[1, 1]) * y + f(m[1, 2]) * z + f(m[1, 3])) / w)


class _Raster:
    """The returns of a search region (x, y, w, h) on a coarse grid, closed by one cell, labelled
    into connected components (cv2, 8-connected)."""

    def __init__(self, pts: np.ndarray, region: np.ndarray, M: np.ndarray):
        self.u, self.v = _project(pts, M)
        self.x0, self.y0 = float(region[0]), float(region[1])
        self.cell = max(CELL_MIN_PX, max(float(region[2]), float(region[3])) / GRID_CELLS)
        self.nx, self.ny = int(np.ceil(region[2] / self.cell)), int(np.ceil(region[3] / self.cell))
        # every k-th return at most RASTER_POINTS of them: a dense depth map puts several returns
        # in a cell, and the closing fills what the stride leaves out
        k = max(1, -(-len(pts) // RASTER_POINTS))
        occ = np.zeros(self.ny * self.nx, np.uint8)
        occ[self._cells(self.u[::k], self.v[::k])] = 1
        self.occ = occ.reshape(self.ny, self.nx)
        closed = cv2.dilate(self.occ, np.ones((3, 3), np.uint8))
        self.n, self.lab = cv2.connectedComponents(closed, connectivity=8)

    def _cells(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        inv = np.float32(1.0 / self.cell)
        cx = np.clip((u - np.float32(self.x0)) * inv, 0, self.nx - 1).astype(np.intp)
        cy = np.clip((v - np.float32(self.y0)) * inv, 0, self.ny - 1).astype(np.intp)
        return cy * self.nx + cx

    def counts(self, box: np.ndarray | None = None) -> np.ndarray:
        """(n,) occupied cells of each component (inside `box` [x, y, w, h] if given); 0: none."""
        lab, occ = self.lab, self.occ
        if box is not None:
            x, y, w, h = (float(b) for b in box)
            bx0, by0 = int(max((x - self.x0) / self.cell, 0)), int(max((y - self.y0) / self.cell, 0))
            bx1 = int(min((x + w - self.x0) / self.cell, self.nx - 1))
            by1 = int(min((y + h - self.y0) / self.cell, self.ny - 1))
            lab, occ = lab[by0:by1 + 1, bx0:bx1 + 1], occ[by0:by1 + 1, bx0:bx1 + 1]
        c = np.bincount((lab * occ).reshape(-1), minlength=self.n)
        c[0] = 0
        return c

    def box(self, keep: np.ndarray, image_size: tuple[int, int], lone_out: bool = True) -> np.ndarray | None:
        """[x, y, w, h] of the returns in the components `keep` (n,) bool: their projections'
        extent (pixel centres, half a pixel out), at the image border when within a cell of it.
        lone_out: a return the raster's stride left out in no component's cell is left out too."""
        W, H = image_size
        every = bool(keep[1:].all())
        if every and lone_out and len(self.u):
            # a return the raster's stride left out lies in no component when it has no other near
            # it (a depth sensor's false alarm beside the body: the outline had reached 100 px out
            # to one): then the per-point selection below, which leaves it out
            ext = np.array([self.u.argmin(), self.u.argmax(), self.v.argmin(), self.v.argmax()])
            every = bool(self.lab.reshape(-1)[self._cells(self.u[ext], self.v[ext])].all())
        if every:   # every component (one, mostly): no per-point selection
            us, vs = self.u, self.v
        else:
            sel = keep[self.lab.reshape(-1)[self._cells(self.u, self.v)]]
            us, vs = self.u[sel], self.v[sel]
        if not len(us):
            return None
        x0, y0 = float(us.min()) - 0.5, float(vs.min()) - 0.5
        x1, y1 = float(us.max()) + 0.5, float(vs.max()) + 0.5
        # a coarse sensor grid's outermost returns lie a few pixels inside the image border: the
        # loop's open-side tests need the box at the border
        c = self.cell
        x0, y0 = (0.0 if x0 < c else x0), (0.0 if y0 < c else y0)
        x1, y1 = (float(W) if x1 > W - c else x1), (float(H) if y1 > H - c else y1)
        return np.array([x0, y0, x1 - x0, y1 - y0]) if x1 > x0 and y1 > y0 else None


def silhouette_box(points: np.ndarray, box2d: np.ndarray, M: np.ndarray, image_size: tuple[int, int],
                   z_range: tuple[float, float], grow: float, regrow: int = REGROW_STEPS,
                   lone_out: bool = True) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """(box (4,) float64 [x, y, w, h] or None, search points (n, 3) float32, search region (4,)).

    points: the frame's cloud (N, 3) in the camera frame of M (3, 4); box2d: the 2D tracker's
    box; image_size (W, H); grow: the search region is box2d grown by this fraction of its width
    and height on each side (clipped to the image); where the outline comes within a raster cell
    of a side of the region that is not the image border, the region is grown past that side by
    `grow` of the outline's size and the outline read again, `regrow` times at most (0: the first
    region only). The components kept are those overlapping box2d in every round. None when no
    returns in the region overlap box2d (the caller keeps its box, or looks in the whole view:
    `find_body`). The search points (the frustum of the last region, [x, y, w, h]) are returned
    so that the caller cuts its own frustum from them, not from the whole cloud again, when its
    box lies in the region. lone_out (a depth sensor's false alarms, track3d.stray_returns): an
    outline needs MIN_CELLS occupied cells, and a lone return the raster's stride left out does not
    stretch it; False: the loop before those rules (one cell is an outline)."""
    W, H = image_size
    x, y, w, h = (float(v) for v in box2d)
    lim = (float(W), float(H))
    # the region as [x0, y0, x1, y1]
    g = [max(0.0, x - grow * w), max(0.0, y - grow * h), min(lim[0], x + w * (1.0 + grow)),
         min(lim[1], y + h * (1.0 + grow))]
    step = 0
    while True:
        region = np.array([g[0], g[1], max(g[2] - g[0], 0.0), max(g[3] - g[1], 0.0)])
        pts = extract_frustum(points, region, M, *z_range)
        if len(pts) == 0 or region[2] <= 0 or region[3] <= 0:
            return None, pts, region
        r = _Raster(pts, region, M)
        counts = r.counts(np.array([x, y, w, h]))
        total = int(counts.sum())
        if total < (MIN_CELLS if lone_out else 1):
            return None, pts, region
        out = r.box(counts >= MIN_SHARE * total, image_size, lone_out)
        if out is None or step >= regrow:
            return out, pts, region
        wider = list(g)
        for a in (0, 1):
            lo, hi = float(out[a]), float(out[a] + out[a + 2])
            if g[a] > 0.0 and lo <= g[a] + r.cell:
                wider[a] = min(g[a], max(0.0, lo - grow * float(out[a + 2])))
            if g[a + 2] < lim[a] and hi >= g[a + 2] - r.cell:
                wider[a + 2] = max(g[a + 2], min(lim[a], hi + grow * float(out[a + 2])))
        if wider == g:
            return out, pts, region
        g, step = wider, step + 1


def past_border(outline: np.ndarray, box2d: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """The outline (4,) [x, y, w, h], reaching past the image border with `box2d` (the 2D
    tracker's box) on each side where the outline touches the border: the returns stop at the
    border, the body need not (a body coming into view). Without it the loop corrected the 2D
    tracker onto the visible part and lost the body as it came in (the `./run.sh` demo,
    sequence 0001 frame 37: one restart)."""
    W, H = image_size
    x0, y0 = float(outline[0]), float(outline[1])
    x1, y1 = x0 + float(outline[2]), y0 + float(outline[3])
    bx0, by0 = float(box2d[0]), float(box2d[1])
    bx1, by1 = bx0 + float(box2d[2]), by0 + float(box2d[3])
    x0 = min(x0, bx0) if x0 <= 0.0 else x0
    y0 = min(y0, by0) if y0 <= 0.0 else y0
    x1 = max(x1, bx1) if x1 >= W else x1
    y1 = max(y1, by1) if y1 >= H else y1
    return np.array([x0, y0, x1 - x0, y1 - y0])


def find_body(points: np.ndarray, near: np.ndarray, M: np.ndarray, image_size: tuple[int, int],
              z_range: tuple[float, float], lone_out: bool = True) -> np.ndarray | None:
    """The box [x, y, w, h] of the body in the whole view: of the connected returns holding at
    least MIN_SHARE of the largest one's cells, the one nearest `near`'s centre (the last box);
    None without returns. For a frame whose 2D box holds none: a range sensor in space sees
    only bodies, so the body that left the tracker's search is found in the depth. lone_out: as
    silhouette_box's (False: the loop before the false-alarm rules)."""
    W, H = image_size
    region = np.array([0.0, 0.0, float(W), float(H)])
    pts = extract_frustum(points, region, M, *z_range)
    if len(pts) == 0:
        return None
    r = _Raster(pts, region, M)
    counts = r.counts()
    if counts.max() <= 0:
        return None
    big = np.nonzero(counts >= MIN_SHARE * counts.max())[0]
    if len(big) > 1:   # the one nearest the last box: its cells' mean position
        ys, xs = np.nonzero(r.occ)
        lab = r.lab[ys, xs]
        cx, cy = near[0] + near[2] / 2.0, near[1] + near[3] / 2.0
        d = [np.hypot((xs[lab == c].mean() + 0.5) * r.cell - cx, (ys[lab == c].mean() + 0.5) * r.cell - cy)
             for c in big]
        big = big[[int(np.argmin(d))]]
    keep = np.zeros(r.n, bool)
    keep[big] = True
    return r.box(keep, image_size, lone_out)


def contain(box2d: np.ndarray, outline: np.ndarray, slack: float = 0.0) -> np.ndarray:
    """The box (4,) float64 [x, y, w, h] moved the least to hold `outline` [x, y, w, h] shrunk by
    `slack` pixels on each side: per axis, a side the outline passes is moved out to it and the
    opposite side follows by the same amount (the box's size kept), the box then grown where the
    outline is still wider. An axis where the shrunk outline is empty is left as it is.

    For an outline that is a lower bound of the body (returns only where the body is, but not
    everywhere it is: stereo depth of the lit part): the body holds the outline, so a box beside
    it has drifted, while a box larger than the outline may be right (the body's dark side)."""
    b = np.array(box2d, dtype=np.float64).reshape(4)
    o = np.asarray(outline, dtype=np.float64).reshape(4)
    out = b.copy()
    for a in (0, 1):
        t0, t1 = b[a], b[a] + b[a + 2]
        o0, o1 = o[a] + slack, o[a] + o[a + 2] - slack
        if not o1 > o0:
            continue
        if o0 < t0:               # past the low side: shift down, then grow up to the high side
            t0, t1 = o0, max(t1 - (t0 - o0), o1)
        elif o1 > t1:             # past the high side
            t0, t1 = min(t0 + (o1 - t1), o0), o1
        out[a], out[a + 2] = t0, t1 - t0
    return out
