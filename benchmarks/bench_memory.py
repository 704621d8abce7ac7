"""One endless watch: does the loop's memory stay flat and its latency bounded over a long run?

    python benchmarks/bench_memory.py --data data/long17 --split test --sequence 0001 --updates 50000 --out memory.json

A spacecraft runs one Track3D for hours and never restarts it. This runs the default tracker
as `track3d track` builds it for the sequence (EdgeTrack + A3BoxNet, the depth sensor's options and
model, its range and sun; one thread, pinned to one core) on one sequence's frames played forwards and backwards (a ping-pong: the motion stays
continuous, so there is no re-initialisation) for --updates updates, and every --every updates
records

- the process's resident memory (RSS, /proc/self/statm: what the operating system gives the
  process; it includes the preloaded frames, which stay constant after loading);
- the size of the loop's state (the bytes of `Track3D.get_state()` as JSON: everything the next
  update depends on, the body's past views included);
- the window's median and p99 update time;
- with --trim, the resident memory again after a garbage collection and glibc's malloc_trim:
  memory the process still holds but no longer uses drops out of it.

It reports the growth of each after warm-up (the last reading minus the first, and a least-squares
slope per 10,000 updates), the windows' latency drift (last window's median over the first's), and
the statuses the loop gave (a watch that turned "lost" exercises less of the loop: read them).
The growth needs at least 3 readings (--updates >= 2 x --every). Each reading is also one line on
stderr (redrawn in place on a terminal).
Writes JSON only with --out (nothing is written into the repository by default): the run record of
benchlib/record.py (machine, ISA, versions, date, load), "pinned_cpus" (the affinity of the
process's threads read back after pinning), then the report; "config" names the model files
with their sha256.
"""
from __future__ import annotations

import gc
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
from benchlib.record import finish_record, model_files, start_record

from track3d import machine
from track3d.argparsing import ArgumentParser, allowed_cpu, bounded, run_main
from track3d.dataset import Dataset
from track3d.jsonable import write_json
from track3d.evaluation.experiment import TrackerSpec
from track3d.stereo import StereoCloud, StereoParams
from track3d.tracker import STATUSES


def resident_mb() -> float:
    """The process's resident memory now, MB (Linux /proc; elsewhere the peak from getrusage)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20
    except (OSError, ValueError, IndexError):
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2 ** 20 if sys.platform == "darwin" else peak / 2 ** 10


def trim_heap() -> bool:
    """Run a full garbage collection and hand the C heap's free pages back to the operating system
    (glibc's malloc_trim); False where there is no glibc (only the collection ran)."""
    import ctypes
    import ctypes.util

    gc.collect()
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        ctypes.CDLL(name).malloc_trim(0)
    except (OSError, AttributeError):   # a C library without malloc_trim (not glibc)
        return False
    return True


def ping_pong(n: int):
    """Frame indices 0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... without end (n >= 2)."""
    k, step = 0, 1
    while True:
        yield k
        if not 0 <= k + step < n:
            step = -step
        k += step


def growth(x: np.ndarray, y: np.ndarray) -> dict:
    """First, last, min, max of y and its least-squares slope per 10,000 of x (None from fewer
    than 2 points: no slope, not a flat one)."""
    slope = float(np.polyfit(x, y, 1)[0]) * 1e4 if len(x) >= 2 else None
    return {"first": float(y[0]), "last": float(y[-1]), "min": float(y.min()), "max": float(y.max()),
            "last_minus_first": float(y[-1] - y[0]), "slope_per_10k_updates": slope}


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, required=True, help="dataset root (track3d-sim output)")
    ap.add_argument("--split", default="test", help="split (default test)")
    ap.add_argument("--sequence", default=None, help="sequence name (default: the split's first)")
    ap.add_argument("--frames", type=bounded(int, 2), default=200,
                    help="frames of the sequence kept in memory and played back and forth (default 200)")
    ap.add_argument("--updates", type=bounded(int, 1), default=50_000, help="measured updates (default 50000)")
    ap.add_argument("--warmup", type=bounded(int, 0), default=1000,
                    help="updates before the first reading (default 1000: the views fill up)")
    ap.add_argument("--every", type=bounded(int, 10), default=1000, help="updates between readings (default 1000)")
    ap.add_argument("--trim", action="store_true",
                    help="at each reading also collect garbage and return the C heap's free pages (glibc "
                         "malloc_trim), then read the resident memory again: what the process holds but "
                         "no longer uses")
    ap.add_argument("--cpu", type=allowed_cpu, metavar="CPU", default=None,
                    help="pin every thread to this CPU, one of those the process may run on: "
                         f"{', '.join(map(str, machine.START_CPUS))} (default: the lowest)")
    ap.add_argument("--depth", choices=("map", "stereo"), default="map",
                    help="map: clouds from the stored depth maps; stereo: a stereo camera's watch, each "
                         "update's cloud matched from the left/right pair around the 2D box (as `track3d track "
                         "--depth stereo`; the matcher follows the body's depth across the watch; default map)")
    ap.add_argument("--stereo-max-cost", type=bounded(int, 0), default=StereoParams().max_match_cost, metavar="COST",
                    help="with --depth stereo: StereoParams.max_match_cost (0: off; default the matcher's)")
    ap.add_argument("--out", type=Path, help="write the JSON report here (default: print only)")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    stereo = a.depth == "stereo"
    if not stereo and a.stereo_max_cost != StereoParams().max_match_cost:
        raise ValueError("--stereo-max-cost sets the matcher of --depth stereo: add --depth stereo")
    if a.updates < 2 * a.every:
        raise ValueError(f"--updates {a.updates} with --every {a.every} gives {a.updates // a.every + 1} reading(s): "
                         "the growth and drift need at least 3 readings (--updates >= 2 x --every)")
    if a.out and a.out.is_dir():   # before the run, not after it
        raise ValueError(f"--out {a.out} is a folder: give the JSON file to write")
    rec = start_record("memory", pinned_cpus=None)
    ds = Dataset(a.data)
    seqs = ds.sequences(a.split)
    seq = next((s for s in seqs if a.sequence in (None, s.name)), None)
    if seq is None:
        raise ValueError(f"no sequence {a.sequence!r} in {a.data}/{a.split}")
    # the frames from the first one with the body in view up to the first absence: played back
    # and forth, the body never leaves
    present = [i for i in range(len(seq)) if not seq.absent[i] and seq.gt2d[i][2] > 0]
    if len(present) < 2:
        raise ValueError(f"sequence {seq.name} has fewer than 2 frames with the body in view")
    idx = [present[0]]
    while len(idx) < a.frames and idx[-1] + 1 < len(seq) and not seq.absent[idx[-1] + 1]:
        idx.append(idx[-1] + 1)
    if len(idx) < 2:
        raise ValueError(f"sequence {seq.name} has no two frames in a row with the body in view")
    # depth stereo: the right image in place of the cloud (the pair is matched inside each update)
    frames = [(seq.image(i), seq.right_image(i) if stereo else seq.points(i)) for i in idx]
    cloud = StereoCloud(seq.camera, max_match_cost=a.stereo_max_cost) if stereo else None
    sensor = seq.depth_sensor
    t3d = TrackerSpec("edgetrack", "a3boxnet", threads=1).build(seq)   # the loop `track3d track` runs
    machine.pin_threads(1, [min(machine.START_CPUS) if a.cpu is None else a.cpu])
    rec["pinned_cpus"] = machine.affinity_of_all_threads()   # read back: what is in force, not what was asked
    first = frames[0][1] if cloud is None else cloud.bind(*frames[0])
    t3d.init(frames[0][0], seq.gt2d[idx[0]], seq.category, points=first)

    order = ping_pong(len(frames))
    next(order)
    statuses = dict.fromkeys(STATUSES, 0)
    at, rss, rss_trimmed, state_kb, win_med, win_p99 = [], [], [], [], [], []
    window: list[float] = []
    total = a.warmup + a.updates
    rss_loaded = resident_mb()
    redraw = sys.stderr.isatty()   # piped: one plain line per reading
    start, end = ("\r", "") if redraw else ("", "\n")
    for done in range(total + 1):   # done 0: no update yet (the first reading when --warmup is 0)
        if done:
            img, pts = frames[next(order)]
            if cloud is not None:
                pts = cloud.bind(img, pts)   # a callable: the matching runs inside the update
            t = time.perf_counter()
            res = t3d.update(img, pts)
            window.append((time.perf_counter() - t) * 1e3)
            if done > a.warmup:
                statuses[res.status] += 1
        if done >= a.warmup and (done - a.warmup) % a.every == 0:
            if done > a.warmup:
                w = np.asarray(window)
                win_med.append(float(np.median(w)))
                win_p99.append(float(np.percentile(w, 99)))
            window = []
            at.append(done - a.warmup)
            rss.append(resident_mb())
            state_kb.append(len(json.dumps(t3d.get_state())) / 1024)
            if a.trim:
                trim_heap()
                rss_trimmed.append(resident_mb())
            print(f"{start}{done - a.warmup}/{a.updates} updates: RSS {rss[-1]:.1f} MB, state {state_kb[-1]:.0f} kB",
                  end=end, file=sys.stderr, flush=True)
    if redraw:
        print(file=sys.stderr)
    x = np.asarray(at, np.float64)
    described = t3d.describe()
    report = finish_record({
        **rec,
        "config": {"tracker": described["tracker"], "estimator": described["estimator"],
                   "models": model_files(described), "depth_sensor": sensor, "threads": 1, "cpu_requested": a.cpu,
                   "data": Path(a.data).name, "split": a.split,
                   "sequence": seq.name, "frames": len(frames), "updates": a.updates, "warmup": a.warmup,
                   "every": a.every, "trim": a.trim, "depth": a.depth,
                   **({"stereo": {"max_match_cost": a.stereo_max_cost}} if stereo else {})},
        "rss_mb_after_loading": rss_loaded,
        "rss_mb": growth(x, np.asarray(rss)),
        "rss_mb_after_trim": growth(x, np.asarray(rss_trimmed)) if rss_trimmed else None,
        "state_kb": growth(x, np.asarray(state_kb)),
        "window_median_ms": growth(x[1:], np.asarray(win_med)) if win_med else None,
        "window_p99_ms": growth(x[1:], np.asarray(win_p99)) if win_p99 else None,
        "latency_drift": win_med[-1] / win_med[0] if len(win_med) >= 2 else None,
        "statuses": statuses,
        "readings": {"updates": at, "rss_mb": rss, "rss_mb_after_trim": rss_trimmed, "state_kb": state_kb, "window_median_ms": win_med,
                     "window_p99_ms": win_p99},
    })
    r, s = report["rss_mb"], report["state_kb"]
    print(f"{a.updates} updates of {seq.name} ({len(frames)} frames back and forth, {sensor or 'unknown'} depth"
          f"{', matched from the pair' if stereo else ''}): "
          f"RSS {r['first']:.1f} -> {r['last']:.1f} MB (max {r['max']:.1f}, slope {r['slope_per_10k_updates']:+.2f} "
          f"MB / 10k updates); state {s['first']:.0f} -> {s['last']:.0f} kB (max {s['max']:.0f}); "
          + (f"window median {win_med[0]:.2f} -> {win_med[-1]:.2f} ms, p99 {win_p99[0]:.2f} -> {win_p99[-1]:.2f} ms; "
             if win_med else "")
          + "statuses " + ", ".join(f"{k} {v}" for k, v in statuses.items()))
    if a.out:
        write_json(a.out, report)
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_memory.py"))
