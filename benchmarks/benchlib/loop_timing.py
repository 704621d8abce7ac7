"""The Track3D loop over preloaded frames with per-stage timers (bench_fps, bench_precision).

Frames are read once into memory (I/O excluded); the loop re-initialises from the ground
truth at each sequence start and runs until `frames` updates have been measured after `warm`
warm-up updates. The networks' time comes from the models' own run_ms counters
(track3d.onnxmodel), so nothing is wrapped or replaced: the models a configuration runs are
passed to its tracker and estimator as parameters.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from track3d.dataset import Dataset
from track3d.machine import affinity_of_all_threads
from track3d.onnxmodel import run_ms_of
from track3d.stereo import StereoCloud
from track3d.tracker import Track3D
from track3d.sensor_options import sensor_options

__all__ = ["STAGES", "load_frames", "build", "time_loop", "trackable_frames", "require_trackable"]

STAGES = ("crop", "net2d", "post2d", "frustum", "boxnet_other", "net3d", "fusion", "overhead", "end_to_end")


def load_frames(data: Path, split: str, max_frames: int, max_sequences: int, depth: str = "map"):
    """(camera, [(sequence, [(image, points, box2d)...])]) preloaded in memory, absent frames kept;
    depth "stereo": the right image in place of the points (the loop matches the pair)."""
    ds = Dataset(data)
    out, total = [], 0
    for seq in ds.sequences(split)[:max_sequences]:
        frames = []
        for i in range(len(seq)):
            frames.append((seq.image(i), seq.right_image(i) if depth == "stereo" else seq.points(i), seq.gt2d[i]))
            total += 1
            if total >= max_frames:
                break
        out.append((seq, frames))
        if total >= max_frames:
            break
    return ds.camera, out


def trackable_frames(sequences) -> int:
    """How many preloaded frames time_loop can update on: those after each sequence's first
    visible frame (its init). 0: time_loop would end in "no sequence has a frame to track" after
    the configurations before it had run; check it before timing."""
    n = 0
    for seq, fr in sequences:
        first = next((k for k in range(len(fr)) if not seq.absent[k] and fr[k][2][2] > 0), None)
        if first is not None:
            n += len(fr) - first - 1
    return n


def require_trackable(sequences, source: str) -> None:
    """ValueError (one line) when time_loop could not run on these preloaded frames; `source`
    says where they came from (e.g. "data/x split 'test', first 400 frames")."""
    if not sequences:
        raise ValueError(f"{source}: no sequence to track (an empty split?)")
    if not trackable_frames(sequences):
        raise ValueError(f"{source}: no frame to track in {len(sequences)} sequence(s) (each needs a frame "
                         "after its first visible one: raise --preload or --sequences)")


def build(camera, cfg: dict, threads: int, fusion: bool = True) -> Track3D:
    """Track3D of cfg["tracker"] / cfg["estimator"] with their options (models included) at
    `threads` threads; cfg["depth_sensor"] (optional): that sensor's loop options and A3BoxNet."""
    sensor = cfg.get("depth_sensor")
    topt = {"threads": threads, **cfg.get("tracker_options", {})}
    eopt = {"threads": threads, **({"depth_sensor": sensor} if sensor and cfg["estimator"] == "a3boxnet" else {}),
            **cfg.get("estimator_options", {})}
    return Track3D.create(camera, cfg["tracker"], cfg["estimator"], tracker_options=topt, estimator_options=eopt,
                          fusion=fusion, **(sensor_options(sensor) if sensor else {}))


def time_loop(t3d: Track3D, sequences, frames: int, warm: int = 20, stereo: StereoCloud | None = None) -> dict:
    """Per-stage median / p99 / mean ms and FPS over `frames` measured updates. stereo: the
    frames hold right images (load_frames(depth="stereo")) and this matcher computes each
    update's cloud around the 2D box inside the update (its time in the "frustum" stage)."""
    rows: dict[str, list] = {k: [] for k in STAGES}
    statuses: dict[str, int] = {}
    done = 0
    cpu0 = wall0 = None
    while done < frames + warm:
        progressed = False
        for seq, fr in sequences:
            first = next((k for k in range(len(fr)) if not seq.absent[k] and fr[k][2][2] > 0), None)
            if first is None:
                continue
            img, pts, box = fr[first]
            if stereo is not None:
                stereo.reset()
                pts = stereo.bind(img, pts)
            t3d.init(img, box, seq.category, points=pts)
            for img, pts, _ in fr[first + 1:]:
                progressed = True
                if stereo is not None:
                    pts = stereo.bind(img, pts)
                n2, n3 = run_ms_of(t3d.tracker2d), run_ms_of(t3d.estimator)
                t = time.perf_counter()
                res = t3d.update(img, pts)
                e2e = (time.perf_counter() - t) * 1e3
                n2, n3 = run_ms_of(t3d.tracker2d) - n2, run_ms_of(t3d.estimator) - n3
                done += 1
                if done <= warm:
                    if done == warm:
                        cpu0, wall0 = time.process_time(), time.perf_counter()
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
        if not progressed:
            raise RuntimeError("no sequence has a frame to track after its first visible one")
    cpu_s, wall_s = time.process_time() - cpu0, time.perf_counter() - wall0
    e2e = np.asarray(rows["end_to_end"])
    return {"frames": int(len(e2e)), "fps_median": float(1e3 / np.median(e2e)), "fps_mean": float(1e3 / np.mean(e2e)),
            "statuses": statuses,
            "stages": {k: {"median_ms": float(np.median(v)), "p99_ms": float(np.percentile(v, 99)),
                           "mean_ms": float(np.mean(v))} for k, v in rows.items()},
            "cpus_allowed": affinity_of_all_threads(), "process_threads": len(os.listdir("/proc/self/task")),
            "cpu_utilisation": cpu_s / max(wall_s, 1e-9)}
