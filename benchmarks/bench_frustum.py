"""Frustum proposal benchmark: the C++ extension vs the numpy reference on a 640x480 cloud.

Two clouds, both 640x480:
- "dense": every pixel has a return (a sphere of radius 3 m at 20 m in front of a wall at
  40 m), 307,200 points; the 2D box is the sphere's silhouette (the frustum keeps ~20%);
- "frame": a frame of a simulated dataset (``--data``), only the pixels with a return, with
  its ground-truth 2D box (skipped without --data).

Also times the sampling to 1024 / 512 points (C++ vs the pure-Python reference of the same
algorithm). Reports median / min / p90 milliseconds over --repeat runs (after a warm-up), with
the CPU model and the load average (the machine is shared: read the minimum as the
undisturbed cost). Writes ./bench-results/frustum_<tag>.json.

    nice python benchmarks/bench_frustum.py [--data data/small] [--repeat 200] [--tag cpu]
"""
from __future__ import annotations

import sys
import time

import numpy as np
from benchlib.output import add_out_argument
from benchlib.record import finish_record, start_record

from track3d import Camera
from track3d.argparsing import ArgumentParser, bounded, run_main
from track3d.frustum import (HAVE_EXTENSION, extract_frustum, extract_frustum_numpy, sample_points,
                             sample_points_numpy)
from track3d.jsonable import write_json


def dense_cloud(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(307200, 3) float32 cloud of a sphere before a wall, and the sphere's 2D box."""
    rays = cam.pixel_rays()
    c, r = np.array([1.0, -0.5, 20.0]), 3.0
    a = np.sum(rays * rays, -1)
    b = -2.0 * rays @ c
    disc = b * b - 4 * a * (c @ c - r * r)
    hit = disc >= 0
    t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a), 40.0)
    vv, uu = np.nonzero(hit)
    box = np.array([uu.min(), vv.min(), uu.max() + 1 - uu.min(), vv.max() + 1 - vv.min()], np.float64)
    return cam.backproject_depth(t.astype(np.float32)), box


def timed(fn, repeat: int) -> dict:
    fn()  # warm-up
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3)
    ts = np.array(ts)
    return {"median_ms": float(np.median(ts)), "min_ms": float(ts.min()), "p90_ms": float(np.percentile(ts, 90)),
            "repeat": repeat}


def bench_cloud(name: str, pts: np.ndarray, box: np.ndarray, M: np.ndarray, repeat: int) -> dict:
    a = extract_frustum(pts, box, M)
    b = extract_frustum_numpy(pts, box, M)
    if not np.array_equal(a, b):
        raise SystemExit(f"{name}: C++ and numpy results differ ({len(a)} vs {len(b)} points)")
    row = {"points": int(len(pts)), "frustum_points": int(len(a)), "box2d": box.tolist(),
           "cpp": timed(lambda: extract_frustum(pts, box, M), repeat),
           "numpy": timed(lambda: extract_frustum_numpy(pts, box, M), repeat)}
    row["speedup_median"] = row["numpy"]["median_ms"] / row["cpp"]["median_ms"]
    row["speedup_min"] = row["numpy"]["min_ms"] / row["cpp"]["min_ms"]
    for num in (1024, 512):
        row[f"sample_{num}"] = {"cpp": timed(lambda: sample_points(a, num, 0), repeat),
                                "python_reference": timed(lambda: sample_points_numpy(a, num, 0), max(repeat // 20, 3))}
    return row


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", help="a simulated dataset root, for the 'frame' cloud")
    ap.add_argument("--split", default="test", help="dataset split")
    ap.add_argument("--repeat", type=bounded(int, 1), default=200, help="calls per timing")
    ap.add_argument("--tag", default="cpu", help="results file tag (default cpu)")
    add_out_argument(ap)
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    if not HAVE_EXTENSION:
        raise SystemExit("the C++ extension is not built: pip install -e .")
    cam = Camera.from_fov(640, 480, 45.0)
    out = start_record("frustum", clouds={})
    pts, box = dense_cloud(cam)
    out["clouds"]["dense"] = bench_cloud("dense", pts, box, cam.M, a.repeat)
    if a.data:
        from track3d.dataset import Dataset

        ds = Dataset(a.data)
        seq = ds.sequences(a.split)[0]
        # the present frame nearest the middle (an absent target has an empty frustum)
        present = [k for k in range(len(seq)) if not seq.absent[k] and seq.gt2d[k][2] > 0 and seq.gt2d[k][3] > 0]
        if not present:
            raise SystemExit(f"{seq.path}: the target is absent in every frame")
        i = min(present, key=lambda k: abs(k - len(seq) // 2))
        out["clouds"]["frame"] = bench_cloud("frame", seq.points(i), seq.gt2d[i], ds.camera.M, a.repeat)
        out["clouds"]["frame"]["source"] = f"{a.data}/{a.split}/{seq.name} frame {i + 1}"
    path = write_json(a.out / f"frustum_{a.tag}.json", finish_record(out))
    for name, row in out["clouds"].items():
        print(f"{name:6s} {row['points']:7d} pts -> {row['frustum_points']:6d}: "
              f"C++ {row['cpp']['median_ms']:.3f} ms (min {row['cpp']['min_ms']:.3f}), "
              f"numpy {row['numpy']['median_ms']:.3f} ms (min {row['numpy']['min_ms']:.3f}), "
              f"x{row['speedup_median']:.1f}; sample 1024: C++ {row['sample_1024']['cpp']['median_ms']:.3f} ms")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_frustum.py"))
