"""The trackers' crop: track3d.resample's kernel against OpenCV's warpAffine, interleaved in one run.

The crops the loop cuts every frame (`track3d.siamfc.crop_square`'s bilinear path): EdgeTrack's
256 px search crop and 128 px template, SiamFC's 255 px search crop, each from a region of
several sizes (the crop's scale 0.55-4; below 0.5 the loop halves the region with cv2.resize
first) of a 640 x 480 frame, centred or cut by the image border. Per case: OpenCV's warp (with one OpenCV thread), the compiled kernel and its numpy
reference, timed in turn call by call (the machine's drift hits all alike); the bytes of the
kernel and the reference must be equal (else exit 1), and whether OpenCV's equal them is
recorded (they do for 5.0.0.93 only). Reports median / min milliseconds and the ratio OpenCV /
kernel; writes ./bench-results/crop_<tag>.json.

    taskset -c 1 python benchmarks/bench_crop.py [--repeat 300] [--tag cpu]
"""
from __future__ import annotations

import sys
import time

import cv2
import numpy as np
from benchlib.output import add_out_argument
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, run_main
from track3d.jsonable import write_json
from track3d.resample import HAVE_EXTENSION, warp_axis_aligned, warp_axis_aligned_numpy

# (label, crop side in px, region side in frame px, region centre)
CASES = [(f"{name} {out} from {region}{' at the border' if edge else ''}", out, region,
          (20.0, 400.0) if edge else (320.0, 240.0))
         for name, out in (("EdgeTrack search", 256), ("EdgeTrack template", 128), ("SiamFC search", 255))
         for region in (64, 200, 460) for edge in (False, True)
         if out / region >= 0.5]   # below 0.5 crop_square halves the region first (cv2.resize), no warp


def _map(out: int, region: float, center) -> tuple[float, tuple[float, float]]:
    s = out / region                                    # as crop_square
    return s, (out / 2.0 - 0.5 - s * (center[0] - 0.5), out / 2.0 - 0.5 - s * (center[1] - 0.5))


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=bounded(int, 3), default=300, help="calls per implementation and case")
    ap.add_argument("--tag", default="cpu", help="results file tag (default cpu)")
    add_out_argument(ap)
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    if not HAVE_EXTENSION:
        raise SystemExit("the C++ extension is not built: pip install -e .")
    cv2.setNumThreads(1)
    frame = cv2.GaussianBlur(np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8), (5, 5), 1.5)
    border = (91.0, 87.0, 80.0)
    rec = start_record("crop", opencv=cv2.__version__, repeat=a.repeat, cases=[])
    for label, out, region, center in CASES:
        s, off = _map(out, region, center)
        m = np.array([[s, 0.0, off[0]], [0.0, s, off[1]]])
        fns = {"opencv": lambda: cv2.warpAffine(frame, m, (out, out), flags=cv2.INTER_LINEAR,
                                                borderMode=cv2.BORDER_CONSTANT, borderValue=border),
               "kernel": lambda: warp_axis_aligned(frame, (s, s), off, (out, out), border),
               "numpy": lambda: warp_axis_aligned_numpy(frame, (s, s), off, (out, out), border)}
        outs = {k: f() for k, f in fns.items()}
        if not np.array_equal(outs["kernel"], outs["numpy"]):
            print(f"{label}: the kernel and its numpy reference differ", file=sys.stderr)
            return 1
        ts = {k: [] for k in fns}
        for i in range(a.repeat):
            for k, f in fns.items():
                if k == "numpy" and i % 10:             # the reference is slow: a tenth of the calls
                    continue
                t0 = time.perf_counter()
                f()
                ts[k].append((time.perf_counter() - t0) * 1e3)
        row = {"case": label, "out": out, "region": region, "scale": s,
               "opencv_equal": bool(np.array_equal(outs["opencv"], outs["kernel"]))}
        for k, v in ts.items():
            row[k] = {"median_ms": float(np.median(v)), "min_ms": float(np.min(v)), "calls": len(v)}
        row["opencv_over_kernel"] = row["opencv"]["median_ms"] / row["kernel"]["median_ms"]
        rec["cases"].append(row)
        print(f"{label:42s} OpenCV {row['opencv']['median_ms']:.3f} ms, kernel {row['kernel']['median_ms']:.3f} ms "
              f"(x{row['opencv_over_kernel']:.2f}), numpy {row['numpy']['median_ms']:.2f} ms, "
              f"OpenCV's bytes {'equal' if row['opencv_equal'] else 'differ'}")
    print(f"wrote {write_json(a.out / f'crop_{a.tag}.json', finish_record(rec))}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_crop.py"))
