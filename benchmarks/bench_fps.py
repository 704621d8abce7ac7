"""Edge FPS benchmark of the full Track3D loop (issue #6 section 3).

Runs the loop over preloaded frames of a dataset split (I/O excluded), re-initialising from the
ground truth at each sequence start, for at least --frames frames per configuration, and reports
per stage (image crop, 2D network, 2D post-processing, frustum, box-net sampling/decoding, box
network, fusion, Python overhead) and end to end: median, p99 and mean in milliseconds, FPS.
With --threads 1 the process is pinned to ONE core (os.sched_setaffinity), which is the
project's target ("100 FPS on one core"); with 2 it may use both.

    python benchmarks/bench_fps.py --data data/small --frames 1000 --threads 1 2

Writes benchmarks/results/fps_<tag>.json (machine, CPU model, versions, every configuration).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from track3d.dataset import Dataset
from track3d.onnxmodel import OnnxModel
from track3d.tracker import Track3D

STAGES = ("crop", "net2d", "post2d", "frustum", "boxnet_other", "net3d", "fusion", "overhead", "end_to_end")
RESULTS = Path(__file__).resolve().parent / "results"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _onnx_models(obj, depth: int = 2):
    """The OnnxModel instances held by a tracker or estimator (attributes, one or two levels)."""
    found = []
    for v in vars(obj).values() if hasattr(obj, "__dict__") else ():
        if isinstance(v, OnnxModel):
            found.append(v)
        elif depth > 1 and hasattr(v, "__dict__") and not isinstance(v, (np.ndarray, type)):
            found.extend(_onnx_models(v, depth - 1))
    return found


class _Timer:
    """Accumulates the wall time of wrapped OnnxModel.run calls between two reads."""

    def __init__(self, models):
        self.ms = 0.0
        for m in models:
            run = m.run

            def timed(feeds, outputs=None, _run=run):
                t = time.perf_counter()
                try:
                    return _run(feeds, outputs)
                finally:
                    self.ms += (time.perf_counter() - t) * 1e3

            m.run = timed

    def take(self) -> float:
        v, self.ms = self.ms, 0.0
        return v


def load_frames(data: Path, split: str, max_frames: int, max_sequences: int):
    """[(sequence, [(image, points, box2d)...])] preloaded in memory, absent frames kept."""
    ds = Dataset(data)
    out, total = [], 0
    for seq in ds.sequences(split)[:max_sequences]:
        frames = []
        for i in range(len(seq)):
            frames.append((seq.image(i), seq.points(i), seq.gt2d[i]))
            total += 1
            if total >= max_frames:
                break
        out.append((seq, frames))
        if total >= max_frames:
            break
    return ds.camera, out


def run_config(camera, sequences, tracker: str, estimator: str, threads: int, frames: int, fusion: bool = True):
    try:
        t3d = Track3D.create(camera, tracker, estimator, tracker_options={"threads": threads},
                             estimator_options={"threads": threads}, fusion=fusion)
    except TypeError:  # classic OpenCV trackers take no thread count (cv2.setNumThreads is global)
        import cv2
        cv2.setNumThreads(threads)
        t3d = Track3D.create(camera, tracker, estimator, estimator_options={"threads": threads}, fusion=fusion)
    net2d = _Timer(_onnx_models(t3d.tracker2d))
    net3d = _Timer(_onnx_models(t3d.estimator))
    rows = {k: [] for k in STAGES}
    statuses: dict[str, int] = {}
    done = 0
    warm = 20
    while done < frames + warm:
        for seq, fr in sequences:
            first = next((k for k in range(len(fr)) if not seq.absent[k] and fr[k][2][2] > 0), None)
            if first is None:
                continue
            img, pts, box = fr[first]
            t3d.init(img, box, seq.category, points=pts)
            net2d.take(), net3d.take()
            for img, pts, _ in fr[first + 1:]:
                t = time.perf_counter()
                res = t3d.update(img, pts)
                e2e = (time.perf_counter() - t) * 1e3
                n2, n3 = net2d.take(), net3d.take()
                done += 1
                if done <= warm:
                    continue
                statuses[res.status] = statuses.get(res.status, 0) + 1
                tm = getattr(t3d.tracker2d, "timings_ms", None) or {}
                crop = tm.get("crop", 0.0)
                post = tm.get("post", max(res.ms["track2d"] - n2 - crop, 0.0))
                if "crop" not in tm:  # trackers without a breakdown: all non-network 2D time is "crop"
                    crop, post = max(res.ms["track2d"] - n2, 0.0), 0.0
                row = {"crop": crop, "net2d": n2, "post2d": post, "frustum": res.ms["frustum"],
                       "boxnet_other": max(res.ms["box3d"] - n3, 0.0), "net3d": n3, "fusion": res.ms["fusion"],
                       "end_to_end": e2e}
                row["overhead"] = max(e2e - sum(v for k, v in row.items() if k != "end_to_end"), 0.0)
                for k in STAGES:
                    rows[k].append(row[k])
                if done >= frames + warm:
                    break
            if done >= frames + warm:
                break
    stats = {k: {"median_ms": float(np.median(v)), "p99_ms": float(np.percentile(v, 99)),
                 "mean_ms": float(np.mean(v))} for k, v in rows.items()}
    e2e = np.asarray(rows["end_to_end"])
    return {"tracker": tracker, "estimator": estimator, "threads": threads, "fusion": fusion,
            "frames": int(len(e2e)), "fps_median": float(1e3 / np.median(e2e)),
            "fps_mean": float(1e3 / np.mean(e2e)), "statuses": statuses, "stages": stats}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="dataset root (track3d-sim output)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--frames", type=int, default=1000, help="measured frames per configuration (>= 1000 for p99)")
    ap.add_argument("--preload", type=int, default=400, help="frames kept in memory (looped over)")
    ap.add_argument("--sequences", type=int, default=8)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--config", action="append", default=None, metavar="TRACKER:ESTIMATOR",
                    help="configurations to run (default: siamfc-edge:a3boxnet siamfc:a3boxnet csrt:baseline)")
    ap.add_argument("--tag", default=None, help="result file name tag (default: the host name)")
    args = ap.parse_args(argv)
    configs = [c.split(":") for c in (args.config or ["siamfc-edge:a3boxnet", "siamfc:a3boxnet", "kcf:baseline"])]
    camera, seqs = load_frames(args.data, args.split, args.preload, args.sequences)
    print(f"preloaded {sum(len(f) for _, f in seqs)} frames of {len(seqs)} sequences", file=sys.stderr)
    all_cpus = os.sched_getaffinity(0)
    results = []
    for threads in args.threads:
        os.sched_setaffinity(0, {min(all_cpus)} if threads == 1 else all_cpus)
        for tracker, estimator in configs:
            try:
                r = run_config(camera, seqs, tracker, estimator, threads, args.frames)
            except Exception as e:  # a missing model must not lose the other configurations
                print(f"skip {tracker}:{estimator} @ {threads} threads: {e}", file=sys.stderr)
                continue
            results.append(r)
            s = r["stages"]
            print(f"{tracker:12s} {estimator:9s} threads={threads} fps(median)={r['fps_median']:7.1f} "
                  f"e2e median={s['end_to_end']['median_ms']:.2f} p99={s['end_to_end']['p99_ms']:.2f} ms | "
                  + " ".join(f"{k}={s[k]['median_ms']:.2f}" for k in STAGES[:-1]))
    os.sched_setaffinity(0, all_cpus)
    import onnxruntime
    out = {"benchmark": "track3d end-to-end FPS", "cpu": cpu_model(), "machine": platform.node(),
           "logical_cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
           "onnxruntime": onnxruntime.__version__, "data": str(args.data), "split": args.split,
           "note": "I/O excluded; threads=1 runs pinned to one core", "results": results}
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"fps_{args.tag or platform.node()}.json"
    path.write_text(json.dumps(out, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
