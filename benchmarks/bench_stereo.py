"""Milliseconds of stereo depth (track3d.stereo) at 640x480: full frame vs a window around a box.

    python benchmarks/bench_stereo.py [--repeat 5] [--threads 1]

A textured pair (random texture, a plane at 10 m: 31 px disparity); SGBM's time hardly depends
on the content. Prints the median ms per call, side by side in one run (ratios are what to
compare on a shared machine).
"""
from __future__ import annotations

import sys
import time

import cv2
import numpy as np

from track3d.argparsing import ArgumentParser, run_main, thread_count
from track3d.camera import Camera
from track3d.stereo import StereoMatcher


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="calls per configuration (default 5)")
    ap.add_argument("--threads", type=thread_count, default=1, help="OpenCV threads (default 1)")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    cv2.setNumThreads(a.threads)
    cam = Camera.from_fov(640, 480, 45.0)
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (480, 640 + 64)).astype(np.float32), (0, 0), 1.2)
    tex = cv2.normalize(tex, None, 20, 235, cv2.NORM_MINMAX).astype(np.uint8)
    d = int(round(cam.disparity(10.0)))
    left, right = tex[:, d:d + 640], tex[:, 0:640]
    left, right = (np.repeat(x[..., None], 3, -1) for x in (left, right))
    print(f"640x480, fx {cam.fx:.1f} px, baseline {cam.baseline_m} m, OpenCV {cv2.__version__}, "
          f"{a.threads} thread(s)")
    for mode in ("sgbm", "3way", "hh"):
        m = StereoMatcher(cam, mode=mode)
        rows = [("full frame", lambda: m.depth(left, right))]
        for s in (64, 128, 256):
            box = [320 - s / 2, 240 - s / 2, s, s]
            rows.append((f"box {s}x{s}", lambda box=box: m.depth_window(left, right, box)))
        for name, f in rows:
            f()
            ts = []
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                f()
                ts.append((time.perf_counter() - t0) * 1e3)
            print(f"{mode:5s} {name:12s} {np.median(ts):8.1f} ms   (search {m.num_disparities} px)")


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_stereo.py"))
