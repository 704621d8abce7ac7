"""`track3d bench`: the Track3D loop's speed on this machine, from the installed package alone.

    report = run_bench(BenchConfig(frames=1000, threads=(1, 2)))
    print(format_table(report))

Frames: a synthetic sequence made here (a lit, textured sphere moving towards the camera at
640x480, its depth back-projected to the point cloud: no dataset and no simulator needed) or
the first sequences of a dataset (``data=``), preloaded, so I/O is excluded. The loop is
re-initialised at each pass over the frames. For each thread count the process is pinned to
that many CPUs (every thread, see track3d.machine), the models get that many intra-op
threads and OpenCV that many; per stage (2D tracker, its network, frustum, box estimator, its
network, fusion) and end to end: median, p99, p99.9 and max milliseconds, and FPS (1000 /
median end-to-end ms). The other processes' CPU load is measured before and after (and the
load average recorded); a warning says when the machine was busy. ``models_only`` times each
ONNX network alone, fed the inputs it saw in the loop (like onnxruntime_perf_test).
``depth="stereo"``: a stereo camera's loop, the cloud matched from the pair around the 2D box
inside each update (track3d.stereo.StereoCloud; the synthetic sphere is also rendered from the
right camera), with the stereo sensor's loop options and A3BoxNet model.
"""
from __future__ import annotations

import gc
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np

from . import machine
from .camera import Camera
from .synthetic import sphere_hits
from .table_text import cell
from .threads import check_threads

if TYPE_CHECKING:
    from .stereo import StereoParams

__all__ = ["BenchConfig", "run_bench", "format_table", "synthetic_frames", "percentiles", "BUSY_THRESHOLD"]

BUSY_THRESHOLD = 0.15      # other processes using more than 15% of all CPUs: timings are suspect
WARMUP = 20


@dataclass
class BenchConfig:
    """What to time. tracker/estimator: registry names; tracker_model: a `<dir>/<name>` prefix
    of a SiamFC pair (`<name>_exemplar.onnx` / `_search.onnx`); boxnet_model: an A3BoxNet ONNX."""

    tracker: str = "edgetrack"
    estimator: str = "a3boxnet"
    tracker_model: str | None = None
    boxnet_model: str | None = None
    frames: int = 1000
    threads: tuple[int, ...] = (1, 2)
    data: str | None = None
    split: str = "test"
    sequences: tuple[str, ...] | None = None      # with data: these sequences, else the split's first
    synthetic_frames: int = 60
    models_only: bool = False
    depth: str = "map"          # "map": clouds given (depth maps); "stereo": matched from the pair in the loop
    stereo: StereoParams | None = None   # depth "stereo": the matcher's settings (None: the defaults)
    busy_seconds: float = 0.5
    precision: str | None = None   # of the networks: fp32 / int8 / bf16 / auto (None: each model's default, fp32)
    engine: str | None = None      # onnxruntime / openvino / auto (None: onnxruntime)
    extra: dict = field(default_factory=dict)


def percentiles(ms) -> dict:
    """median, p99, p99.9, max and mean of a list of milliseconds."""
    a = np.asarray(ms, dtype=np.float64)
    if a.size == 0:
        return {k: None for k in ("median_ms", "p99_ms", "p99_9_ms", "max_ms", "mean_ms")}
    return {"median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)),
            "p99_9_ms": float(np.percentile(a, 99.9)), "max_ms": float(a.max()), "mean_ms": float(a.mean())}


MATCH_DEADLINES_MS = (5.0, 10.0, 20.0)   # the matching times a stereo bench prices a budget for


def matching_price(costs, ms) -> dict:
    """What stereo matching costs on this CPU, from the updates of a run (costs: `StereoCloud.last_cost`
    of each update, ms: its matching's time): the least-squares price, ms = ns_per_unit * 1e-6 *
    cost (the cost counts the matcher's per-pixel work too: no fixed term), the p99 of the times
    above it (ms) and the budget (`StereoParams.max_match_cost`) that keeps an update's matching
    within each of MATCH_DEADLINES_MS at that p99 (None where none would). The cost is a count of
    work, the same on every machine: this is its price here."""
    c, t = np.asarray(costs, dtype=np.float64), np.asarray(ms, dtype=np.float64)
    out = {"updates": int(c.size), "ns_per_unit": None, "above_p99_ms": None,
           "budget_for_ms": {f"{d:g}": None for d in MATCH_DEADLINES_MS}}
    if c.size < 2 or not np.any(c > 0):
        return out
    b = float(np.dot(c, t) / np.dot(c, c))
    r99 = float(np.percentile(t - b * c, 99))
    out.update(ns_per_unit=b * 1e6, above_p99_ms=r99)
    if b > 0:
        out["budget_for_ms"] = {f"{d:g}": (int((d - r99) / b) if d > r99 else None) for d in MATCH_DEADLINES_MS}
    return out


# --- frames -----------------------------------------------------------------------------------

def _texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A crater-like grey texture (H, W) in 0..1: a few random dark discs over value noise."""
    rng = np.random.default_rng(seed)
    coarse = rng.random((h // 16 + 2, w // 16 + 2))
    import cv2

    tex = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC) * 0.3 + 0.7
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(40):
        cx, cy, r = rng.random() * w, rng.random() * h, 3 + rng.random() * 0.05 * max(h, w)
        d = np.hypot(xx - cx, yy - cy) / r
        tex = np.where(d < 1.0, tex * (0.55 + 0.45 * d), tex)
    return np.clip(tex, 0.0, 1.0)


def synthetic_frames(camera: Camera, n: int = 60, seed: int = 0, stereo: bool = False):
    """n frames of a lit, textured sphere (radius 2 m) drifting across and towards the camera.

    Returns [(image (H, W, 3) uint8 RGB, points (N, 3) float32, box2d (4,) float64)], category 0;
    stereo: the right camera's image (H, W, 3) uint8 in place of the points (the sphere seen from
    +baseline). The texture is painted in longitude/latitude on the surface, so both cameras see
    the same texture at the same point, and it turns with the sphere's rotation."""
    rays = camera.pixel_rays()
    tex = _texture(256, 512, seed)
    radius = 2.0
    light = np.array([-0.5, -0.4, -0.77])
    light /= np.linalg.norm(light)

    def view(c: np.ndarray, k: int):
        hit, t, nrm = sphere_hits(rays, c, radius)
        shade = np.clip(nrm @ -light, 0.03, 1.0)
        lon = (np.arctan2(nrm[..., 0], nrm[..., 2]) / (2 * np.pi) + 0.5 + 0.01 * k) % 1.0
        lat = np.arccos(np.clip(nrm[..., 1], -1, 1)) / np.pi
        val = shade * tex[(lat * 255).astype(int).clip(0, 255), (lon * 511).astype(int).clip(0, 511)]
        img = np.zeros((camera.height, camera.width, 3), np.uint8)
        g = (255 * val).astype(np.uint8)
        img[hit] = np.stack([g, g, g], -1)[hit]
        return img, hit, t

    out = []
    for k in range(n):
        f = k / max(n - 1, 1)
        c = np.array([-1.5 + 3.0 * f, 0.8 - 1.2 * f, 22.0 - 8.0 * f])
        img, hit, t = view(c, k)
        vv, uu = np.nonzero(hit)
        box = np.array([uu.min(), vv.min(), uu.max() + 1 - uu.min(), vv.max() + 1 - vv.min()], np.float64)
        if stereo:
            out.append((img, view(c - camera.right_offset, k)[0], box))
        else:
            out.append((img, camera.backproject_depth(np.where(hit, t, 0.0).astype(np.float32)), box))
    return out


def _dataset_frames(root: str, split: str, max_frames: int, names: tuple[str, ...] | None = None,
                    stereo: bool = False):
    """(camera, passes, names): the frames of the first sequences of a dataset split (or of
    `names`) until there are `max_frames`, preloaded, as (category, frames) per sequence, and the
    names of the sequences taken; stereo: the right image in place of the points."""
    from .dataset import Dataset

    ds = Dataset(root)
    seqs = [ds.sequence(split, n) for n in dict.fromkeys(names)] if names else ds.sequences(split)
    if not seqs:
        raise ValueError(f"split {split!r} of {root} has no sequences")
    passes, used = [], []
    total = 0
    for seq in seqs:
        fr = [(seq.image(i), seq.right_image(i) if stereo else seq.points(i), seq.gt2d[i]) for i in range(len(seq))
              if not seq.absent[i] and np.all(np.isfinite(seq.gt2d[i])) and seq.gt2d[i][2] > 0]
        if len(fr) >= 2:
            passes.append((seq.category, fr))
            used.append(seq.name)
            total += len(fr)
        if total >= max_frames:
            break
    if not passes:
        raise ValueError(f"no sequence of {root}/{split} has two frames with a visible target")
    return ds.camera, passes, used


# --- timing -----------------------------------------------------------------------------------

def _onnx_models(obj) -> list:
    from .onnxmodel import models_of

    return list(models_of(obj).values())


class _NetTimer:
    """The network time of a tracker or estimator from its models' own run_ms counters (nothing
    wraps run()), and each model's first inputs (OnnxModel.keep_feeds) for --models-only."""

    def __init__(self, part):
        from .onnxmodel import run_ms_of

        self.part, self._run_ms = part, run_ms_of
        self.models = _onnx_models(part)
        for m in self.models:
            m.keep_feeds = True
        self._last = run_ms_of(part)

    def take(self) -> float:
        """Milliseconds in the networks since the last take()."""
        now = self._run_ms(self.part)
        v, self._last = now - self._last, now
        return v

    @property
    def feeds(self) -> dict[str, dict]:
        out: dict[str, dict] = {}
        for m in self.models:
            if getattr(m, "first_feeds", None) is not None:
                out.setdefault(m.meta.get("kind", m.path.name), m.first_feeds)
        return out


def _build(cfg: BenchConfig, camera: Camera, threads: int):
    from .tracker import Track3D
    from .sensor_options import sensor_options

    topt: dict = dict(cfg.extra.get("tracker_options", {}))
    eopt: dict = dict(cfg.extra.get("estimator_options", {}))
    stereo = cfg.depth == "stereo"
    if stereo and cfg.estimator == "a3boxnet" and not cfg.boxnet_model:
        eopt.setdefault("depth_sensor", "stereo")   # the stereo model (track3d.boxnet.SENSOR_MODELS)
    arith = {k: v for k, v in (("precision", cfg.precision), ("engine", cfg.engine)) if v is not None}
    if cfg.tracker in NETWORK_TRACKERS or cfg.tracker_model:  # EdgeTrack was timed at 1 thread in every row
        topt["threads"] = threads
        topt.update(arith)
        if cfg.tracker_model:
            topt["model"] = cfg.tracker_model
    if cfg.estimator == "a3boxnet" or cfg.boxnet_model:
        eopt["threads"] = threads
        eopt.update(arith)
        if cfg.boxnet_model:
            eopt["model"] = cfg.boxnet_model
    return Track3D.create(camera, cfg.tracker, cfg.estimator, tracker_options=topt, estimator_options=eopt,
                          **(sensor_options("stereo") if stereo else {}))


# Built-in 2D trackers that run networks: they get the row's thread count as intra-op threads
# (OpenCV's trackers get it through cv2.setNumThreads).
NETWORK_TRACKERS = ("siamfc", "siamfc-edge", "edgetrack")

STAGE_NAMES = ("track2d", "net2d", "frustum", "box3d", "net3d", "fusion", "end_to_end")


def _timed_points(cloud, bound, acc: list):
    """`bound` (a StereoCloud's callable) with each call's time (ms), cost and drop added to acc."""
    def points(box2d):
        t = time.perf_counter()
        out = bound(box2d)
        acc[0] += (time.perf_counter() - t) * 1e3
        acc[1] += cloud.last_cost
        acc[2] += int(cloud.last_dropped)
        return out
    return points


def _time_loop(t3d, passes, frames: int, stereo=None) -> tuple[dict, dict, dict, dict | None]:
    """stereo: a track3d.stereo.StereoCloud; the frames then hold right images, matched inside
    each update (their time in the frustum stage, and in the fourth value: the matching's time,
    cost and price per update)."""
    net2d = _NetTimer(t3d.tracker2d)
    net3d = _NetTimer(t3d.estimator)
    rows: dict[str, list] = {k: [] for k in STAGE_NAMES}
    statuses: dict[str, int] = {}
    match_ms, match_cost, dropped = [], [], 0
    done = 0
    while done < frames + WARMUP:
        for category, fr in passes:
            img, pts, box = fr[0]
            if stereo is not None:
                stereo.reset()
                pts = stereo.bind(img, pts)
            t3d.init(img, box, category, points=pts)
            net2d.take(), net3d.take()
            for img, pts, _ in fr[1:]:
                acc = [0.0, 0, 0]
                if stereo is not None:
                    pts = _timed_points(stereo, stereo.bind(img, pts), acc)
                t = time.perf_counter()
                res = t3d.update(img, pts)
                e2e = (time.perf_counter() - t) * 1e3
                n2, n3 = net2d.take(), net3d.take()
                done += 1
                if done > WARMUP:
                    statuses[res.status] = statuses.get(res.status, 0) + 1
                    for k, v in (("track2d", res.ms["track2d"]), ("net2d", n2), ("frustum", res.ms["frustum"]),
                                 ("box3d", res.ms["box3d"]), ("net3d", n3), ("fusion", res.ms["fusion"]),
                                 ("end_to_end", e2e)):
                        rows[k].append(v)
                    if stereo is not None:
                        match_ms.append(acc[0])
                        match_cost.append(acc[1])
                        dropped += acc[2]
                if done >= frames + WARMUP:
                    break
            if done >= frames + WARMUP:
                break
    stages = {k: percentiles(v) for k, v in rows.items()}
    matching = None
    if stereo is not None:
        costs = np.asarray(match_cost, dtype=np.float64)
        matching = {"ms": percentiles(match_ms),
                    "cost_median": float(np.median(costs)) if costs.size else None,
                    "cost_max": float(costs.max()) if costs.size else None,
                    "dropped": dropped, "price": matching_price(costs, match_ms)}
    return stages, statuses, {**net2d.feeds, **net3d.feeds}, matching


def _time_models(t3d, feeds: dict, frames: int) -> dict:
    """Each network alone on the inputs it got in the loop: median / p99 / p99.9 / max ms."""
    out = {}
    for part in (t3d.tracker2d, t3d.estimator):
        for m in _onnx_models(part):
            key = m.meta.get("kind", m.path.name)
            if key not in feeds:
                continue
            run = m.run
            for _ in range(5):
                run(feeds[key])
            ms = []
            for _ in range(frames):
                t = time.perf_counter()
                run(feeds[key])
                ms.append((time.perf_counter() - t) * 1e3)
            out[key] = {"file": m.path.name, "inputs": {k: list(v.shape) for k, v in feeds[key].items()},
                        **percentiles(ms), "runs_per_s": 1e3 / float(np.median(ms))}
    return out


def run_bench(cfg: BenchConfig, log: Callable[[str], None] | None = None) -> dict:
    """Time the loop (or, with models_only, each network) at each thread count; a JSON-able dict."""
    import cv2

    if cfg.frames < 1:
        raise ValueError(f"frames must be >= 1, got {cfg.frames}")
    if not cfg.threads:
        raise ValueError("threads: give at least one thread count")
    for n in cfg.threads:
        check_threads(n)
    if cfg.depth not in ("map", "stereo"):
        raise ValueError(f"depth must be 'map' or 'stereo', got {cfg.depth!r}")
    stereo = cfg.depth == "stereo"
    say = log or (lambda s: None)
    if cfg.data:
        camera, passes, used = _dataset_frames(cfg.data, cfg.split, max(cfg.synthetic_frames, 100), cfg.sequences,
                                               stereo)
        # the sequences timed: those loaded until there were enough frames, not those asked for
        source = {"kind": "dataset", "data": str(cfg.data), "split": cfg.split, "sequences": used}
    else:
        camera = Camera.from_fov(640, 480, 45.0)
        say(f"synthesising {cfg.synthetic_frames} frames (640x480 sphere{', stereo pair' if stereo else ''}) ...")
        passes = [(0, synthetic_frames(camera, cfg.synthetic_frames, stereo=stereo))]
        source = {"kind": "synthetic", "frames": cfg.synthetic_frames, "width": 640, "height": 480}
    if cfg.stereo is not None and not stereo:
        raise ValueError("stereo settings are for depth 'stereo' (the pair matched in the loop)")
    if stereo:
        from .stereo import StereoCloud, StereoParams

        stereo_params = cfg.stereo or StereoParams()
        source["depth"] = "stereo from the pair (track3d.stereo.StereoCloud, matched in each update)"
        source["stereo"] = dict(stereo_params.__dict__)
    busy_before = machine.cpu_busy(cfg.busy_seconds)
    load_before = machine.load_average()
    allowed = machine.allowed_cpus()
    results, described = [], None
    cv_threads = cv2.getNumThreads()
    try:
        for threads in cfg.threads:
            cpus = allowed[:threads]
            pinned = bool(machine.pin_threads(threads, allowed))
            t3d = _build(cfg, camera, threads)
            described = described or t3d.describe()
            if cfg.models_only and not (_onnx_models(t3d.tracker2d) or _onnx_models(t3d.estimator)):
                raise ValueError(f"--models-only: {cfg.tracker} + {cfg.estimator} run no ONNX network "
                                 f"(time the loop without --models-only)")
            say(f"{t3d.tracker_name}+{t3d.estimator_name} at {threads} thread(s) on CPU(s) {cpus} ...")
            wall0, cpu0 = time.perf_counter(), time.process_time()
            stages, statuses, feeds, matching = _time_loop(t3d, passes, min(cfg.frames, 200) if cfg.models_only else cfg.frames,
                                                 StereoCloud(camera, stereo_params) if stereo else None)
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
            row = {"threads": threads, "cpus": cpus, "pinned": pinned,
                   "note": None if len(cpus) == threads else f"only {len(cpus)} CPU(s) allowed",
                   "cpu_utilisation": cpu / max(wall, 1e-9)}
            if cfg.models_only:
                row["models"] = _time_models(t3d, feeds, cfg.frames)
            else:
                e2e = stages["end_to_end"]["median_ms"]
                row.update(frames=cfg.frames, fps=1e3 / e2e if e2e else None, stages=stages, statuses=statuses)
                if matching is not None:
                    row["matching"] = matching
            results.append(row)
            del t3d
            gc.collect()
    finally:
        machine.pin(allowed)
        cv2.setNumThreads(cv_threads)
    busy_after = machine.cpu_busy(cfg.busy_seconds)
    warnings = []
    busy = [b for b in (busy_before, busy_after) if b is not None]
    if busy and max(busy) > BUSY_THRESHOLD:
        warnings.append(f"the machine was busy: other processes used {100 * max(busy):.0f}% of all CPUs "
                        f"(before {_pct(busy_before)}, after {_pct(busy_after)}); timings are pessimistic")
    if any(r.get("note") for r in results):
        warnings.append("fewer CPUs allowed than threads asked for: see 'note' per row")
    if cfg.frames < 1000 and not cfg.models_only:
        warnings.append(f"{cfg.frames} frames: p99.9 is the max of too few samples (use --frames >= 1000)")
    return {"benchmark": "track3d bench", "mode": "models-only" if cfg.models_only else "loop",
            "machine": machine.machine_info(), "load": {"busy_before": busy_before, "busy_after": busy_after,
                                                         "loadavg_before": load_before,
                                                         "loadavg_after": machine.load_average()},
            "source": source, "track3d": described, "results": results, "warnings": warnings,
            "note": "milliseconds per frame, I/O excluded; fps = 1000 / median end-to-end ms; "
                    "each thread count runs pinned to that many CPUs"}


def _pct(x) -> str:
    return "n/a" if x is None else f"{100 * x:.0f}%"


def _f(v) -> str:
    return cell(v, "{:.2f}")


def _matching_lines(m: dict) -> list[str]:
    v, p = m["ms"], m["price"]
    lines = [f"{'stereo matching':20s} {_f(v['median_ms']):>8s} {_f(v['p99_ms']):>8s} {_f(v['p99_9_ms']):>8s} "
             f"{_f(v['max_ms']):>8s}  (in frustum; cost median {cell(m['cost_median'], '{:,.0f}')}, max "
             f"{cell(m['cost_max'], '{:,.0f}')}; {m['dropped']} update(s) without a cloud)"]
    if p["ns_per_unit"] is None:
        lines.append("  its price here: n/a (too few updates with a match)")
        return lines
    fits = ", ".join(f"{d} ms: max_match_cost={c}" if c else f"{d} ms: none fits"
                     for d, c in p["budget_for_ms"].items())
    lines.append(f"  its price here: {p['ns_per_unit']:.2f} ns per unit of cost (p99 {p['above_p99_ms']:.2f} ms above "
                 f"that); a budget per update for {fits}")
    return lines


_PART_OF = {"net2d": "track2d", "net3d": "box3d"}   # stages timed inside another


def format_table(report: dict) -> str:
    """The report as a text table (one block per thread count), machine line first."""
    m = report["machine"]
    lines = [f"CPU: {m['cpu']} ({m['arch']}, {m['logical_cpus']} logical CPUs; ISA: {' '.join(m['isa']) or 'n/a'})",
             "versions: " + ", ".join(f"{k} {v}" for k, v in m["versions"].items() if v),
             f"frames: {report['source']['kind']}"
             + (f" {report['source'].get('data')}" if report["source"].get("data") else "")
             + (f", split {report['source']['split']}" if report["source"].get("split") else "")
             + (f", sequences {' '.join(report['source']['sequences'])}" if report["source"].get("sequences") else "")
             + (f"; depth: {report['source']['depth']}" if report["source"].get("depth") else "")]
    d = report.get("track3d") or {}
    models = ", ".join(f"{x['file']} ({x['sha256'][:12]}"
                       + (f", {x['engine']} {x['precision']}" if x.get("engine") and x.get("precision") else "") + ")"
                       for x in d.get("models", []))
    lines.append(f"tracker: {d.get('tracker')} + {d.get('estimator')}" + (f"; models: {models}" if models else ""))
    for r in report["results"]:
        lines.append("")
        if report["mode"] == "models-only":
            lines.append(f"threads={r['threads']} (CPUs {r['cpus']})")
            lines.append(f"{'network':18s} {'median':>8s} {'p99':>8s} {'p99.9':>8s} {'max':>8s} {'runs/s':>8s}")
            for k, v in r["models"].items():
                lines.append(f"{k:18s} {_f(v['median_ms']):>8s} {_f(v['p99_ms']):>8s} {_f(v['p99_9_ms']):>8s} "
                             f"{_f(v['max_ms']):>8s} {v['runs_per_s']:8.1f}")
            continue
        lines.append(f"threads={r['threads']} (CPUs {r['cpus']}): {r['fps']:.1f} FPS over {r['frames']} frames")
        lines.append(f"{'stage (ms)':20s} {'median':>8s} {'p99':>8s} {'p99.9':>8s} {'max':>8s}")
        for k, v in r["stages"].items():
            # the networks' own time is part of the stage above it, not added to the sum
            name = f"  {k} (in {_PART_OF[k]})" if k in _PART_OF else k
            lines.append(f"{name:20s} {_f(v['median_ms']):>8s} {_f(v['p99_ms']):>8s} {_f(v['p99_9_ms']):>8s} "
                         f"{_f(v['max_ms']):>8s}")
        if r.get("matching"):
            lines.extend(_matching_lines(r["matching"]))
    ld = report["load"]
    lines.append("")
    lines.append(f"load: other processes {_pct(ld['busy_before'])} before, {_pct(ld['busy_after'])} after; "
                 f"loadavg {ld['loadavg_before']} -> {ld['loadavg_after']}")
    if report["mode"] != "models-only":
        lines.append("FPS = 1000 / the median end-to-end ms; I/O excluded; each thread count pinned to that many CPUs")
    for w in report["warnings"]:
        lines.append(f"WARNING: {w}")
    return "\n".join(lines)
