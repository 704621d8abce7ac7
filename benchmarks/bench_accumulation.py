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
    rays = np.stack([(uu + 0.5 - cam.cx) / cam.fx, (vv + 0.5 - cam.cy) / cam.fy, np.ones(len(uu))], axis=1)
    width = float(np.ptp(rays[:, 0] * front)) + float(np.ptp(rays[:, 1] * front))
    t = np.linspace(0.0, RAY_REACH * max(width, 0.1), RAY_SAMPLES)
    z = front[:, None] + t[None, :]                                   # (rays, samples)
    pts = (rays[:, None, :] * z[..., None]).reshape(-1, 3)
    alive = np.ones(len(pts), bool)
    body = to_body(pts, R_i, T_i)
    H, W = depth_i.shape
    for d_k, R_k, T_k in past:
        q = to_camera(body[alive], R_k, T_k)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.floor(cam.fx * q[:, 0] / q[:, 2] + cam.cx).astype(np.int64)
            v = np.floor(cam.fy * q[:, 1] / q[:, 2] + cam.cy).astype(np.int64)
        inside = (q[:, 2] > 0) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        keep = ~inside
        dk = d_k[v[inside], u[inside]]
        keep[inside] = (dk > 0) & (q[inside, 2] >= dk - CARVE_TOL_M)
        idx = np.flatnonzero(alive)
        alive[idx[~keep]] = False
    if not alive.any():
        return float(front.max())
    return float(pts[alive, 2].max())


def sequence_ious(seq, estimator, seen_angle_deg: float = 90.0, seed: int = 0, every: int = 1) -> dict[str, list[float]]:
    """Per present frame (every `every`-th: the views are those frames too), IoU_3d of each
    variant (VARIANTS) against the label."""
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
    for i in range(0, len(seq), every):
        if seq.absent[i]:
            continue
        pts, bounds = extract_frustum_bounds(seq.points(i), seq.gt2d[i], seq.camera.M)
        if len(pts) < 10:
            continue
        g = seq.gt3d[i]
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
                 "max_back": with_back(max(net[2] + net[5] / 2.0, hi[2])),
                 "net_on_views": fit_measured_faces(estimator.estimate(views.astype(np.float32), -1), bounds),
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
                       seen_angle_deg=a.seen_angle, every=a.every)
    per = {}
    for seq in progress(seqs, desc="sequences"):
        ious = sequence_ious(seq, estimator, a.seen_angle, every=a.every)
        per[seq.name] = {"generator": seq.meta.get("generator"),
                         "spin_deg_s": seq.meta.get("motion", {}).get("spin_deg_s"),
                         **{k: float(np.mean(v)) if v else None for k, v in ious.items()}}
    rec["sequences"] = per
    rec["mean_iou_3d"] = {k: float(np.mean([p[k] for p in per.values() if p[k] is not None])) for k in VARIANTS}
    a.out.mkdir(parents=True, exist_ok=True)
    write_json(a.out / "accumulation.json", finish_record(rec))
    print(" ".join(f"{k} {v:.4f}" for k, v in rec["mean_iou_3d"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main, "bench_accumulation.py"))
