"""The body's outline in the image from the depth returns (range sensors against empty space).

A range sensor in space returns depth only where there is a body: the returns around the 2D
tracker's box, rasterised in the image, form the body's silhouette, dark side included. The 2D
tracker sees the lit body and drifts or shrinks to a part of it (a bilobate body turning its
second lobe into view: IoU_2d 0.66 on the accuracy set's sequence 0010 while the returns'
outline keeps 0.94). `silhouette_box` is the bounding box of the connected returns that overlap
the tracker's box, searched in that box grown by `grow` of its size on each side.

The raster is coarse (cells of at least CELL_MIN_PX pixels, at most GRID_CELLS per side of the
search region) and closed by one cell, so that a sparse sensor's grid (a flash LiDAR's returns
every few pixels) still reads as one body; the box itself is the extent of the kept returns'
projections (pixel centres, half a pixel out on each side), not of the cells.
"""
from __future__ import annotations

import cv2
import numpy as np

from .frustum import extract_frustum

__all__ = ["CELL_MIN_PX", "GRID_CELLS", "MIN_SHARE", "RASTER_POINTS", "silhouette_box"]

CELL_MIN_PX = 2.5     # pixels: a cell spans at least this (gaps of a coarse sensor grid close)
GRID_CELLS = 96       # cells on the longer side of the search region at most (cost bound)
MIN_SHARE = 0.05      # a component is the body's when it holds this share of the box's occupied cells
RASTER_POINTS = 6000  # returns rasterised at most (every k-th of a larger search region's)


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


def silhouette_box(points: np.ndarray, box2d: np.ndarray, M: np.ndarray, image_size: tuple[int, int],
                   z_range: tuple[float, float], grow: float) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """(box (4,) float64 [x, y, w, h] or None, search points (n, 3) float32, search region (4,)).

    points: the frame's cloud (N, 3) in the camera frame of M (3, 4); box2d: the 2D tracker's
    box; image_size (W, H); grow: the search region is box2d grown by this fraction of its width
    and height on each side (clipped to the image). None when no returns in the region overlap
    box2d (the caller keeps its box). The search points (the frustum of the region, [x, y, w, h])
    are returned so that the caller cuts its own frustum from them, not from the whole cloud again,
    when its box lies in the region."""
    W, H = image_size
    x, y, w, h = (float(v) for v in box2d)
    gx0, gy0 = max(0.0, x - grow * w), max(0.0, y - grow * h)
    gx1, gy1 = min(float(W), x + w * (1.0 + grow)), min(float(H), y + h * (1.0 + grow))
    region = np.array([gx0, gy0, max(gx1 - gx0, 0.0), max(gy1 - gy0, 0.0)])
    pts = extract_frustum(points, region, M, *z_range)
    if len(pts) == 0 or region[2] <= 0 or region[3] <= 0:
        return None, pts, region
    u, v = _project(pts, M)
    cell = max(CELL_MIN_PX, max(region[2], region[3]) / GRID_CELLS)
    nx, ny = int(np.ceil(region[2] / cell)), int(np.ceil(region[3] / cell))
    inv = np.float32(1.0 / cell)
    # the raster from every k-th return at most RASTER_POINTS of them: a dense depth map puts
    # several returns in a cell, and the closing fills what the stride leaves out
    k = max(1, -(-len(pts) // RASTER_POINTS))
    cx = np.clip((u[::k] - np.float32(gx0)) * inv, 0, nx - 1).astype(np.intp)
    cy = np.clip((v[::k] - np.float32(gy0)) * inv, 0, ny - 1).astype(np.intp)
    flat = cy * nx + cx
    occ = np.zeros(ny * nx, np.uint8)
    occ[flat] = 1
    closed = cv2.dilate(occ.reshape(ny, nx), np.ones((3, 3), np.uint8))
    n, lab = cv2.connectedComponents(closed, connectivity=8)
    # the tracker's box in cells: the components there are the body's (by their share of its cells)
    bx0, by0 = int(max((x - gx0) / cell, 0)), int(max((y - gy0) / cell, 0))
    bx1, by1 = int(min((x + w - gx0) / cell, nx - 1)), int(min((y + h - gy0) / cell, ny - 1))
    inbox = lab[by0:by1 + 1, bx0:bx1 + 1] * occ.reshape(ny, nx)[by0:by1 + 1, bx0:bx1 + 1]   # occupied, not closed
    counts = np.bincount(inbox.reshape(-1), minlength=n)
    counts[0] = 0
    total = int(counts.sum())
    if total == 0:
        return None, pts, region
    keep = counts >= MIN_SHARE * total
    if keep[1:].all():   # every component is the body's (one, mostly): no per-point selection
        us, vs = u, v
    else:   # every return's own cell (the raster's were every k-th)
        ax = np.clip((u - np.float32(gx0)) * inv, 0, nx - 1).astype(np.intp)
        ay = np.clip((v - np.float32(gy0)) * inv, 0, ny - 1).astype(np.intp)
        sel = keep[lab.reshape(-1)[ay * nx + ax]]
        us, vs = u[sel], v[sel]
    x0, y0, x1, y1 = float(us.min()) - 0.5, float(vs.min()) - 0.5, float(us.max()) + 0.5, float(vs.max()) + 0.5
    # returns within a cell of the image border: the body may go on past the view there, and a
    # coarse sensor grid's outermost returns lie a few pixels inside it (the loop's open-side
    # tests need the box at the border)
    x0, y0 = (0.0 if x0 < cell else x0), (0.0 if y0 < cell else y0)
    x1, y1 = (float(W) if x1 > W - cell else x1), (float(H) if y1 > H - cell else y1)
    if x1 <= x0 or y1 <= y0:
        return None, pts, region
    return np.array([x0, y0, x1 - x0, y1 - y0]), pts, region
