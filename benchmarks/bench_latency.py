"""Latency distribution of the Track3D loop: median, p99, p99.9, max per update, and where the tail is.

    python benchmarks/bench_latency.py --data data/small --frames 10000 --out latency.json

Runs the default tracker (Track3D.from_default: the shipped models, one thread) over preloaded frames of a
split (I/O excluded), re-initialising at each sequence start, pinned to one core (every thread of
the process). It records each update's total and per-stage times, the frustum size, and the
garbage collections that ran during the update (gc.callbacks), then reports

- the distribution of the total (median, p90, p99, p99.9, max, and the ratios to the median);
- the slowest 0.1% of frames: their stages' excess over the stage medians (which stage makes
  the tail), their frustum sizes vs the median, and GC collections during them;
- whether spikes are periodic (the spread of the gaps between p99 frames);
- the latency by frustum size (quartiles of num_points): the near, large targets.

With --depth stereo the loop is a stereo camera's (Track3D.from_default(depth_sensor="stereo")):
each update's cloud is matched from the pair around the 2D box (track3d.stereo.StereoCloud,
reset at each sequence start) inside the update, and the report adds what the matcher did: the
matching cost of each update (StereoCloud.last_cost), the tail's against the median, the
latency by cost quartile and the updates left without a cloud (StereoCloud.last_dropped: the
followed search's retry past the budget). --stereo-max-cost / --stereo-max-match set the matcher's caps.

Writes JSON only with --out (nothing is written into the repository by default): the run record of
benchlib/record.py (machine, ISA, versions, date, load), "pinned_cpus" (the affinity of the
process's threads read back after pinning), then the report; "config" names the model files
with their sha256.
"""
from __future__ import annotations

import gc
import os
import sys
import time
from pathlib import Path

import numpy as np
from benchlib.record import finish_record, model_files, start_record

from track3d import machine
from track3d.argparsing import ArgumentParser, allowed_cpu, bounded, run_main
from track3d.dataset import Dataset
from track3d.jsonable import write_json
from track3d.stereo import StereoCloud, StereoParams
from track3d.tracker import STAGES, Track3D


def load(data: Path, split: str, max_frames: int, depth: str = "map"):
    """(camera, [(category, [(image, points or the right image, box2d)...])]) from each sequence's
    first visible frame."""
    ds = Dataset(data)
    seqs, total = [], 0
    for seq in ds.sequences(split):
        second = seq.right_image if depth == "stereo" else seq.points
        fr = [(seq.image(i), second(i), seq.gt2d[i]) for i in range(min(len(seq), max_frames - total))]
        first = next((k for k in range(len(fr)) if not seq.absent[k] and fr[k][2][2] > 0), None)
        if first is not None and len(fr) > first + 1:
            seqs.append((seq.category, fr[first:]))
        total += len(fr)
        if total >= max_frames:
            break
    return ds.camera, seqs


def stats(v: np.ndarray) -> dict:
    med = float(np.median(v))
    out = {"median_ms": med, "p90_ms": float(np.percentile(v, 90)), "p99_ms": float(np.percentile(v, 99)),
           "p99.9_ms": float(np.percentile(v, 99.9)), "max_ms": float(v.max()), "mean_ms": float(v.mean())}
    for k in ("p99", "p99.9", "max"):
        out[f"{k}/median"] = out[f"{k}_ms"] / med
    return out


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, required=True, help="dataset root (track3d-sim output)")
    ap.add_argument("--split", default="test", help="split (default test)")
    ap.add_argument("--frames", type=bounded(int, 1), default=10_000, help="measured updates (default 10000)")
    ap.add_argument("--warmup", type=bounded(int, 0), default=50, help="updates before measuring (default 50)")
    ap.add_argument("--preload", type=int, default=400, help="frames kept in memory, looped over (default 400)")
    ap.add_argument("--cpu", type=allowed_cpu, metavar="CPU", default=None,
                    help="pin every thread to this CPU, one of those the process may run on: "
                         f"{', '.join(map(str, machine.START_CPUS))} (default: the lowest)")
    ap.add_argument("--gc-freeze", action="store_true", help="gc.freeze() after warm-up (objects alive then are never scanned)")
    ap.add_argument("--depth", choices=("map", "stereo"), default="map",
                    help="map: clouds from the stored depth maps; stereo: matched from the pair inside each "
                         "update (a stereo camera's loop; the dataset needs right images; default map)")
    ap.add_argument("--stereo-max-cost", type=bounded(int, 0), default=StereoParams().max_match_cost, metavar="COST",
                    help="with --depth stereo: StereoParams.max_match_cost (0: off; default the matcher's)")
    ap.add_argument("--stereo-max-match", type=bounded(int, 0), default=StereoParams().max_match_px, metavar="PX",
                    help="with --depth stereo: StereoParams.max_match_px (0: off; default the matcher's)")
    ap.add_argument("--out", type=Path, help="write the JSON report here (default: print only)")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)

    stereo = a.depth == "stereo"
    if not stereo and (a.stereo_max_cost != StereoParams().max_match_cost
                       or a.stereo_max_match != StereoParams().max_match_px):
        raise ValueError("--stereo-max-cost / --stereo-max-match set the matcher of --depth stereo: add --depth stereo")
    if a.out and a.out.is_dir():   # before the run, not after it
        raise ValueError(f"--out {a.out} is a folder: give the JSON file to write")
    rec = start_record("latency", pinned_cpus=None)
    camera, seqs = load(a.data, a.split, a.preload, a.depth)
    if not seqs:
        raise ValueError(f"no trackable sequence in {a.data}/{a.split}")
    t3d = Track3D.from_default(camera, threads=1, depth_sensor="stereo" if stereo else None)
    cloud = (StereoCloud(camera, max_match_cost=a.stereo_max_cost, max_match_px=a.stereo_max_match)
             if stereo else None)
    machine.pin_threads(1, [min(machine.START_CPUS) if a.cpu is None else a.cpu])
    rec["pinned_cpus"] = machine.affinity_of_all_threads()   # read back: what is in force, not what was asked

    gc_events: list[float] = []
    gc.callbacks.append(lambda phase, info: gc_events.append(time.perf_counter()) if phase == "start" else None)
    total, stages, npts, gcs, costs, dropped = [], {k: [] for k in STAGES}, [], [], [], 0
    done, measuring = 0, False
    while len(total) < a.frames:
        for category, fr in seqs:
            pts = fr[0][1]
            if cloud is not None:
                cloud.reset()
                pts = cloud.bind(fr[0][0], pts)
            t3d.init(fr[0][0], fr[0][2], category, points=pts)
            for img, pts, _ in fr[1:]:
                if cloud is not None:
                    pts = cloud.bind(img, pts)   # a callable: the matching runs inside the update
                n_gc = len(gc_events)
                t = time.perf_counter()
                res = t3d.update(img, pts)
                ms = (time.perf_counter() - t) * 1e3
                done += 1
                if not measuring:
                    if done >= a.warmup:
                        measuring = True
                        if a.gc_freeze:
                            gc.freeze()
                    continue
                total.append(ms)
                for k in STAGES:
                    stages[k].append(res.ms[k])
                npts.append(res.num_points)
                gcs.append(len(gc_events) - n_gc)
                costs.append(cloud.last_cost if cloud is not None else 0)
                dropped += bool(cloud is not None and cloud.last_dropped)
                if len(total) >= a.frames:
                    break
            if len(total) >= a.frames:
                break
    total_a = np.asarray(total)
    npts_a = np.asarray(npts)
    st = {k: np.asarray(v) for k, v in stages.items()}
    tail = total_a >= np.percentile(total_a, 99.9)
    p99 = np.flatnonzero(total_a >= np.percentile(total_a, 99))
    gaps = np.diff(p99)
    q = np.percentile(npts_a, [25, 50, 75])
    bins = np.digitize(npts_a, q)
    described = t3d.describe()
    report = {
        **rec,
        "config": {"tracker": described["tracker"], "estimator": described["estimator"],
                   "models": model_files(described), "threads": 1, "cpu_requested": a.cpu,
                   "frames": len(total),
                   "gc_freeze": a.gc_freeze, "data": Path(a.data).name, "split": a.split, "depth": a.depth,
                   **({"stereo": {"max_match_cost": a.stereo_max_cost, "max_match_px": a.stereo_max_match}}
                      if stereo else {})},
        "total": stats(total_a),
        "stages_median_ms": {k: float(np.median(v)) for k, v in st.items()},
        "tail": {
            "frames": int(tail.sum()),
            "stage_excess_ms": {k: float(np.mean(v[tail]) - np.median(v)) for k, v in st.items() if k != "total"},
            "num_points_mean": float(npts_a[tail].mean()), "num_points_median_all": float(np.median(npts_a)),
            "gc_collections": int(np.asarray(gcs)[tail].sum()),
        },
        "gc_collections_total": int(sum(gcs)),
        "p99_gaps": {"count": int(len(gaps)), "mean": float(gaps.mean()) if len(gaps) else None,
                     "std": float(gaps.std()) if len(gaps) else None},
        "by_frustum_quartile": [{"num_points_upto": float(q[i]) if i < 3 else float(npts_a.max()),
                                 "median_ms": float(np.median(total_a[bins == i])) if np.any(bins == i) else None}
                                for i in range(4)],
    }
    if stereo:
        c = np.asarray(costs, dtype=np.float64)
        cq = np.percentile(c, [25, 50, 75])
        cbins = np.digitize(c, cq)
        report["stereo_matching"] = {
            "cost_median": float(np.median(c)), "cost_p99": float(np.percentile(c, 99)), "cost_max": float(c.max()),
            "tail_cost_mean": float(c[tail].mean()),
            "dropped": dropped,   # updates whose retried search did not fit the budget: no cloud
            "by_cost_quartile": [{"cost_upto": float(cq[i]) if i < 3 else float(c.max()),
                                  "median_ms": float(np.median(total_a[cbins == i])) if np.any(cbins == i) else None}
                                 for i in range(4)]}
    finish_record(report)
    t = report["total"]
    print(f"{len(total)} updates: median {t['median_ms']:.2f} ms, p99 {t['p99_ms']:.2f} ({t['p99/median']:.2f}x), "
          f"p99.9 {t['p99.9_ms']:.2f} ({t['p99.9/median']:.2f}x), max {t['max_ms']:.2f} ({t['max/median']:.2f}x); "
          f"GC collections {report['gc_collections_total']}; load average {os.getloadavg()[0]:.1f}")
    print("tail (slowest 0.1%) stage excess over medians, ms: "
          + ", ".join(f"{k} {v:+.2f}" for k, v in report["tail"]["stage_excess_ms"].items())
          + f"; frustum points {report['tail']['num_points_mean']:.0f} vs median {report['tail']['num_points_median_all']:.0f}")
    print("median ms by frustum-size quartile: "
          + ", ".join(f"<= {b['num_points_upto']:.0f}: {b['median_ms']:.2f}" for b in report["by_frustum_quartile"]
                      if b["median_ms"] is not None))
    if stereo:
        m = report["stereo_matching"]
        print(f"matching cost (px x (disparities + 48)): median {m['cost_median'] / 1e6:.1f}M, p99 "
              f"{m['cost_p99'] / 1e6:.1f}M, max {m['cost_max'] / 1e6:.1f}M, the tail's {m['tail_cost_mean'] / 1e6:.1f}M, "
              f"{m['dropped']} without a cloud (the retry past the budget); "
              "median ms by cost quartile: " + ", ".join(f"<= {b['cost_upto'] / 1e6:.1f}M: {b['median_ms']:.2f}"
                                                        for b in m["by_cost_quartile"] if b["median_ms"] is not None))
    if a.out:
        write_json(a.out, report)
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_latency.py"))
