"""What a body-fixed accumulation of views could give the hidden depth, at best (issue 12).

A temporal box estimator would carry every past view of the body into the current frame
through the body's rotation. This measures the ceiling of that idea with the TRUE pose (the
simulator's per-frame body attitude R and position T, `meta.json` -> `frame_data`), so no
pose estimator could do better: every frame of every sequence, oracle 2D boxes, and per frame

- `net`:         A3BoxNet on this frame's frustum, the seen faces measured (the loop's box);
- `views_box`:   the enclosing box of all views so far, mapped into this frame (a lower bound
                 of the body's box on clean depth);
- `max_back`:    `net` with its back face pushed out to the views' farthest point if farther;
- `net_on_views`: A3BoxNet on the accumulated views (up to 512 points sampled from them);
- `seen_back`:   `net` with the views' farthest point as its back face once a past view looked
                 at the body from at least `--seen-angle` degrees away from this view's direction
                 (the hidden side was in view then), else `net`;
- `hull_back`:   `net` with its back face cut to the farthest point the past views leave
                 possible: a point of the body lies inside every view's silhouette and no nearer
                 to that camera than the surface it saw there (space carving with depth, on rays
                 through this frame's silhouette), an upper bound of the back face;
- `hull_clip`:   `net`'s back face clipped between the views' farthest point (`max_back`) and
                 the carved bound (`hull_back`);
- `true_back`:   `net` with the true back face (what the hidden depth is worth).

    python benchmarks/bench_accumulation.py --data data/engine-calib-unseen9 --split test_unseen

Writes <out>/accumulation.json: mean IoU_3d per sequence and their mean, per variant.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from benchlib.output import add_out_argument
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, run_main
from track3d.body_views import SurfaceGrid, point_to_plane, projective_fit
from track3d.boxes import fit_measured_faces, iou_3d
from track3d.dataset import Dataset
from track3d.estimators import create_estimator
from track3d.frustum import extract_frustum_bounds
from track3d.jsonable import write_json
from track3d.progress import progress

VARIANTS = ("net", "views_box", "max_back", "net_on_views", "seen_back", "hull_back", "hull_clip", "true_back")
MAX_VIEW_POINTS = 2000      # per view kept in the body frame
MAX_POINTS = 40000          # in the accumulated cloud (a random subset beyond it)
RAY_STRIDE = 3              # carving: one ray per RAY_STRIDE x RAY_STRIDE pixels of the silhouette
RAY_SAMPLES = 96            # carving: samples along a ray, front face to front + RAY_REACH x the width
RAY_REACH = 3.0
CARVE_TOL_M = 0.05          # carving: a point this much nearer than a view's surface still counts
ICP_POINTS = 3000           # --pose icp: returns of a frame registered onto the previous frame's
ICP_ITERS = 30
ICP_MAX_DIST_M = 1.0        # --pose icp: pairs farther apart than this are left out
ICP_GOOD_M = 0.03           # --pose icp: a point this close to the other view's surface fits
ICP_MIN_FIT = 0.6           # --pose icp: a registration fitting fewer of the points starts the views over


def to_body(points: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(n, 3) camera-frame points -> the body frame of a body at attitude R (3, 3), position T (3,)."""
    return (np.asarray(points, np.float64) - T) @ R


def to_camera(points: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """The inverse of `to_body`: p = R b + T."""
    return np.asarray(points, np.float64) @ R.T + T


def carved_back(cam, depth_i: np.ndarray, R_i, T_i, past: list) -> float:
    """The farthest depth (this frame's z, metres) a body point can have, given the past views
    `past` [(depth map (H, W), R, T)]: points on rays through this frame's silhouette (every
    RAY_STRIDE-th pixel), behind its surface, that every past view sees inside its silhouette and
    not nearer than its surface (CARVE_TOL_M); points outside a past view's image are kept.
    inf without a past view."""
    if not past:
        return float("inf")
    vv, uu = np.nonzero(depth_i[::RAY_STRIDE, ::RAY_STRIDE] > 0)
    vv, uu = vv * RAY_STRIDE, uu * RAY_STRIDE
    front = depth_i[vv, uu].astype(np.float64)
    rays = cam.pixel_rays()[vv, uu]
    width = float(np.ptp(rays[:, 0] * front)) + float(np.ptp(rays[:, 1] * front))
    t = np.linspace(0.0, RAY_REACH * max(width, 0.1), RAY_SAMPLES)
    z = front[:, None] + t[None, :]                                   # (rays, samples)
    pts = (rays[:, None, :] * z[..., None]).reshape(-1, 3)
    alive = np.ones(len(pts), bool)
    body = to_body(pts, R_i, T_i)
    H, W = depth_i.shape
    for d_k, R_k, T_k in past:
        q = to_camera(body[alive], R_k, T_k)
        u, v = _pixels(cam, q)
        inside = (q[:, 2] > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        keep = ~inside
        dk = d_k[v[inside], u[inside]]
        keep[inside] = (dk > 0) & (q[inside, 2] >= dk - CARVE_TOL_M)
        idx = np.flatnonzero(alive)
        alive[idx[~keep]] = False
    if not alive.any():
        return float(front.max())
    return float(pts[alive, 2].max())


def _pixels(cam, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pixel (column, row) int64 each point (n, 3) projects into (`Camera.project`, floored);
    points at z <= 0 get a large negative index, off every image."""
    with np.errstate(invalid="ignore"):
        uv = np.nan_to_num(np.floor(cam.project(points)), nan=-1, posinf=-1, neginf=-1)
    return uv[:, 0].astype(np.int64), uv[:, 1].astype(np.int64)


def _grid_points_normals(cam, depth: np.ndarray, box2d: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
    """The returns inside box2d [x, y, w, h] as points (n, 3) with unit normals (n, 3) from the
    depth grid's central differences (pixels whose four neighbours all have a return), and the
    grid itself for projective matching: (points (h, w, 3), normals (h, w, 3), valid (h, w), x0, y0)."""
    H, W = depth.shape
    x, y, w, h = (float(v) for v in box2d)
    x0, y0 = max(int(x) - 1, 1), max(int(y) - 1, 1)
    x1, y1 = min(int(np.ceil(x + w)) + 1, W - 1), min(int(np.ceil(y + h)) + 1, H - 1)
    # the box and a pixel around it, so that every pixel of the box has its four neighbours
    ring = (slice(y0 - 1, y1 + 1), slice(x0 - 1, x1 + 1))
    d = depth[ring].astype(np.float64)
    P = cam.pixel_rays()[ring] * d[..., None]
    ok = d > 0
    c = (slice(1, -1), slice(1, -1))
    du = P[1:-1, 2:] - P[1:-1, :-2]
    dv = P[2:, 1:-1] - P[:-2, 1:-1]
    good = ok[c] & ok[1:-1, 2:] & ok[1:-1, :-2] & ok[2:, 1:-1] & ok[:-2, 1:-1]
    n = np.cross(du, dv)
    norm = np.linalg.norm(n, axis=-1)
    good &= norm > 0
    n = n / np.where(norm > 0, norm, 1.0)[..., None]
    return P[c][good], n[good], (P[c], n, good, x0, y0)


def icp(src: np.ndarray, dst: np.ndarray, dst_normals: np.ndarray, init: np.ndarray,
        iters: int = ICP_ITERS, max_dist: float = ICP_MAX_DIST_M) -> np.ndarray:
    """Point-to-plane ICP: the rigid transform (4, 4) that puts the points src (n, 3) onto the
    surface dst (m, 3) with normals (m, 3), started from `init` (4, 4)."""
    return icp_fit(src, dst, dst_normals, init, iters, max_dist)[0]


def icp_fit(src: np.ndarray, dst: np.ndarray, dst_normals: np.ndarray, init: np.ndarray,
            iters: int = ICP_ITERS, max_dist: float = ICP_MAX_DIST_M) -> tuple[np.ndarray, float]:
    """`icp`'s transform and the share of src (0..1) that lands within ICP_GOOD_M of the surface
    dst along its normal with it (how well the two views fit: near 1 on clean depth when right)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(dst)

    def match(s):
        dist, idx = tree.query(s, distance_upper_bound=max_dist)
        keep = np.isfinite(dist)
        return keep, dst[idx[keep]], dst_normals[idx[keep]]

    return point_to_plane(src, match, init, iters, ICP_GOOD_M)


def projective_icp_fit(src: np.ndarray, grid: tuple, cam, init: np.ndarray, iters: int = ICP_ITERS,
                       max_dist: float = ICP_MAX_DIST_M) -> tuple[np.ndarray, float]:
    """`icp_fit` with each point matched to the return of the other view's depth grid it projects
    onto (`_grid_points_normals`' grid), not to its nearest point: the loop's
    `track3d.body_views.projective_fit` on a grid of one-pixel cells, stopping as `icp_fit` does."""
    P, N, good, x0, y0 = grid
    cells = SurfaceGrid(P, N, good, good, float(x0), float(y0), 1.0)
    return projective_fit(src, cells, cam, init, iters, max_dist, ICP_GOOD_M, done_rad=1e-6, done_m=1e-5)


def icp_poses(seq, max_points: int = ICP_POINTS, seed: int = 0, projective: bool = False,
              timings: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame pose (R (T, 3, 3), T (T, 3), the convention of `to_body`) from the depth alone:
    each present frame's returns in its label box registered onto the previous present frame's
    by point-to-plane ICP (started from the last frame's motion), the motions chained; the body
    frame is the first present frame's camera frame moved to its returns' centroid (so that the
    direction from the body to the camera means what it does with the true pose). Frames without
    returns keep the last pose. A registration that fits fewer than ICP_MIN_FIT of the points
    (the body left the view, spun too far between frames) starts a new body frame: the third
    array (T,) int numbers these segments, and views of different segments must not be joined.
    projective: `projective_icp_fit` instead of the KD-tree's; `timings` gets each registration's ms."""
    import time

    rng = np.random.default_rng(seed)
    n = len(seq)
    R, T = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    segment, seg = np.zeros(n, np.int64), 0
    G = np.eye(4)            # camera frame of this frame -> body frame
    motion = np.eye(4)       # the last frame-to-frame motion (this frame -> the previous one)
    prev = None
    for i in range(n):
        if not seq.absent[i] and np.all(np.isfinite(seq.gt2d[i])):
            pts, nrm, grid = _grid_points_normals(seq.camera, seq.depth(i), seq.gt2d[i])
            if len(pts) >= 20:
                fit = 0.0
                if prev is not None:
                    src = pts if len(pts) <= max_points else pts[rng.choice(len(pts), max_points, replace=False)]
                    t0 = time.perf_counter()
                    step, fit = (projective_icp_fit(src, prev[2], seq.camera, motion) if projective
                                 else icp_fit(src, prev[0], prev[1], motion))
                    if timings is not None:
                        timings.append((time.perf_counter() - t0) * 1e3)
                if fit >= ICP_MIN_FIT:
                    motion = step
                    G = G @ motion
                else:           # the first view, or a registration gone wrong: a new body frame
                    if prev is not None:
                        seg += 1
                    G, motion = np.eye(4), np.eye(4)
                    G[:3, 3] = -pts.mean(axis=0)
                prev = (pts, nrm, grid)
        R[i] = G[:3, :3].T          # to_body(p) = R^T (p - T) = G p
        T[i] = -G[:3, :3].T @ G[:3, 3]
        segment[i] = seg
    return R, T, segment


def _net_on(estimator, views: np.ndarray, bounds: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """A3BoxNet on the accumulated views, the seen faces measured; `fallback` where the views
    leave the network's domain (a pose gone wrong spreads them past its extent)."""
    try:
        return fit_measured_faces(estimator.estimate(views.astype(np.float32), -1), bounds)
    except ValueError:
        return fallback


def sequence_ious(seq, estimator, seen_angle_deg: float = 90.0, seed: int = 0, every: int = 1,
                  pose: str = "true", timings: list | None = None) -> dict[str, list[float]]:
    """Per present frame (every `every`-th: the views are those frames too), IoU_3d of each
    variant (VARIANTS) against the label. pose "true": the simulator's; "icp" / "icp-projective":
    `icp_poses` (its registrations' ms appended to `timings`)."""
    segment = np.zeros(len(seq), np.int64)
    if pose in ("icp", "icp-projective"):
        R, T, segment = icp_poses(seq, seed=seed, projective=pose == "icp-projective", timings=timings)
    else:
        fd = seq.meta.get("frame_data")
        if not isinstance(fd, dict) or "R" not in fd or "T" not in fd:
            raise ValueError(f"{seq.path}: meta.json has no per-frame pose (frame_data R, T): "
                             "a dataset of an older simulator")
        R = np.asarray(fd["R"], np.float64).reshape(-1, 3, 3)     # body -> camera
        T = np.asarray(fd["T"], np.float64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    body = np.zeros((0, 3))
    looks = np.zeros((0, 3))      # the unit directions from the body to the camera, body frame
    out: dict[str, list[float]] = {k: [] for k in VARIANTS}
    past: list = []
    current = 0
    for i in range(0, len(seq), every):
        if seq.absent[i]:
            continue
        pts, bounds = extract_frustum_bounds(seq.points(i), seq.gt2d[i], seq.camera.M)
        if len(pts) < 10:
            continue
        g = seq.gt3d[i]
        if segment[i] != current:   # a new body frame (the pose was lost): the views start over
            body, looks, past, current = np.zeros((0, 3)), np.zeros((0, 3)), [], segment[i]
        net = fit_measured_faces(estimator.estimate(pts, -1, bounds=bounds), bounds)
        view = to_body(pts, R[i], T[i])
        if len(view) > MAX_VIEW_POINTS:
            view = view[rng.choice(len(view), MAX_VIEW_POINTS, replace=False)]
        body = np.concatenate([body, view])
        if len(body) > MAX_POINTS:
            body = body[rng.choice(len(body), MAX_POINTS, replace=False)]
        views = to_camera(body, R[i], T[i])
        look = -T[i] @ R[i]
        look /= np.linalg.norm(look)
        looks = np.concatenate([looks, look[None]])
        seen = float(np.degrees(np.arccos(np.clip(looks @ look, -1.0, 1.0))).max())
        lo, hi = views.min(axis=0), views.max(axis=0)
        front = float(bounds[0][2])

        def with_back(back: float) -> np.ndarray:
            b = net.copy()
            b[5] = back - front
            b[2] = front + b[5] / 2.0
            return b

        depth_i = seq.depth(i)
        hull = carved_back(seq.camera, depth_i, R[i], T[i], past)
        past.append((depth_i, R[i], T[i]))
        net_back = net[2] + net[5] / 2.0
        boxes = {"net": net, "views_box": np.concatenate([(lo + hi) / 2.0, hi - lo]),
                 "max_back": with_back(max(net_back, hi[2])),
                 "net_on_views": _net_on(estimator, views, bounds, net),
                 "seen_back": with_back(hi[2]) if seen >= seen_angle_deg else net,
                 "hull_back": with_back(min(net_back, hull)),
                 "hull_clip": with_back(min(max(net_back, hi[2]), max(hull, hi[2]))),
                 "true_back": with_back(g[2] + g[5] / 2.0)}
        for k, b in boxes.items():
            out[k].append(float(iou_3d(b[None], g[None])[0]))
    return out


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True, help="a dataset with depth and labels (track3d-sim generate)")
    ap.add_argument("--split", default="test_unseen", help="the split to measure (default: test_unseen)")
    ap.add_argument("--limit", type=bounded(int, 0), default=0, help="first N sequences only (0: all)")
    ap.add_argument("--seen-angle", type=bounded(float, 0, high=180), default=90.0,
                    help="degrees between a past view and this one for `seen_back` to trust the views (default 90)")
    ap.add_argument("--pose", choices=("true", "icp", "icp-projective"), default="true",
                    help="the body's pose: the simulator's (true, the ceiling) or from the depth alone "
                         "(icp: point-to-plane ICP of each frame onto the last, chained, nearest-point "
                         "matching; icp-projective: matching by projection onto the last depth grid; "
                         "default true)")
    ap.add_argument("--every", type=bounded(int, 1), default=1,
                    help="every N-th frame only, as the frame measured and as a view (long sequences: "
                         "the carving's cost grows with the views; default 1)")
    add_out_argument(ap, "accumulation")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    seqs = Dataset(a.data).sequences(a.split)[: a.limit or None]
    estimator = create_estimator("a3boxnet")
    rec = start_record("accumulation", data=a.data.as_posix(), split=a.split, variants=list(VARIANTS),
                       seen_angle_deg=a.seen_angle, every=a.every, pose=a.pose)
    per, timings = {}, []
    for seq in progress(seqs, desc="sequences"):
        ious = sequence_ious(seq, estimator, a.seen_angle, every=a.every, pose=a.pose, timings=timings)
        per[seq.name] = {"generator": seq.meta.get("generator"),
                         "spin_deg_s": seq.meta.get("motion", {}).get("spin_deg_s"),
                         **{k: float(np.mean(v)) if v else None for k, v in ious.items()}}
    rec["sequences"] = per
    rec["mean_iou_3d"] = {k: float(np.mean([p[k] for p in per.values() if p[k] is not None])) for k in VARIANTS}
    if timings:   # one registration of a frame onto the last, this process's CPU as it ran
        rec["registration_ms"] = {"median": float(np.median(timings)), "p99": float(np.percentile(timings, 99)),
                                  "count": len(timings), "points": ICP_POINTS}
    a.out.mkdir(parents=True, exist_ok=True)
    write_json(a.out / "accumulation.json", finish_record(rec))
    print(" ".join(f"{k} {v:.4f}" for k, v in rec["mean_iou_3d"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main, "bench_accumulation.py"))
