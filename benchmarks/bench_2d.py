"""2D tracker benchmark (paper Fig. 14): accuracy and speed in one run.

On a dataset split (default: the test split of data/small), one-pass evaluation (init on the
first frame with the target present, no restart, absent frames not scored) of

    siamfc-edge, siamfc (faithful), nano (NanoTrack v2, peer model), kcf, csrt, mosse, mil

with AO_2d, SR@0.5, ACE_2d from the full 1-thread pass, and FPS (tracker time only, frames
preloaded) at 1 thread (process pinned to one core) and 2 threads (on the first
--speed-seqs sequences, the same frames for every tracker). Also:
  --sweep      the edge design sweep: width x search size x scales x int8 -> AO vs ms plot
  --ratio      onnxruntime vs torch eager speed of the SiamFC search graph (needs torch)

    python benchmarks/bench_2d.py --data data/small --sweep --ratio

Writes <out>/bench_2d.json, bench_2d_success.png, bench_2d_precision.png, bench_2d_tradeoff.png
and bench_2d.md (the table). Default out: ./bench-results/siamfc/ (the committed results: --out benchmarks/results/siamfc).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from track3d.boxes import center_error_2d, iou_2d
from track3d.dataset import Dataset

ROOT = Path(__file__).resolve().parents[1]
# Benchmarks never write into the repository unless asked: by default their output goes to
# ./bench-results under the current folder; pass --out benchmarks/results/... to update the committed files.
OUT_ROOT = Path("bench-results")
RESULTS = OUT_ROOT / "siamfc"
MODELS = ROOT / "runtime" / "track3d" / "models"
DEFAULT_TRACKERS = ("siamfc-edge", "siamfc", "nano", "kcf", "csrt", "mosse", "mil")
IOU_T = np.linspace(0.0, 1.0, 101)
CE_T = np.linspace(0.0, 50.0, 51)
PAPER = {"SiamFC (paper, RTX 2080Ti)": {"AO_2d": 0.513, "ACE_2d": 29.986, "fps": 101.3}}


from track3d.evaluation.experiment import cpu_name as cpu_model  # noqa: E402  (one implementation)


def pin(threads: int) -> None:
    """1 thread: pin the process to one core (the project's target); more: all cores."""
    if not hasattr(os, "sched_setaffinity"):
        return
    cores = sorted(os.sched_getaffinity(0) | set(range(os.cpu_count() or 1)))
    os.sched_setaffinity(0, {cores[-1]} if threads == 1 else set(cores))
    cv2.setNumThreads(threads)


def make_factory(name: str, spec: dict | None = None):
    """name -> callable(threads) building a fresh tracker."""
    spec = spec or {}
    if name.startswith("siamfc"):
        from track3d.siamfc import create

        def f(threads):
            kw = dict(spec.get("options", {}))
            if "model" in spec:
                kw["model"] = spec["model"]
            else:
                kw["variant"] = "edge" if name == "siamfc-edge" else "faithful"
            return create(threads=threads, **kw)
        return f
    from track3d.trackers2d import create_tracker

    return lambda threads: create_tracker(name)


def run_one(tracker, frames, gt, valid) -> dict:
    first = int(np.argmax(valid))
    tracker.init(frames[first], gt[first].copy())
    n = len(gt)
    pred = np.full((n, 4), np.nan)
    pred[first] = gt[first]
    times = np.zeros(n - first - 1)
    for i in range(first + 1, n):
        t0 = time.perf_counter()
        ok, box = tracker.update(frames[i])
        times[i - first - 1] = time.perf_counter() - t0
        b = np.asarray(box, np.float64).reshape(-1)
        good = bool(ok) and b.shape == (4,) and np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0
        pred[i] = b if good else pred[i - 1]     # a reported failure holds the last box
    sc = valid.copy()
    sc[: first + 1] = False
    iou = iou_2d(pred[sc], gt[sc])
    ce = center_error_2d(pred[sc], gt[sc])
    return {"iou": iou, "ce": ce, "time_s": float(times.sum()), "frames": len(times),
            "frame_ms": times * 1e3}


def summarise(per_seq: list[dict]) -> dict:
    rs = [r for r in per_seq if len(r["iou"])]
    if not rs:
        return {}
    frame_ms = np.concatenate([r["frame_ms"] for r in rs])
    t = sum(r["time_s"] for r in rs)
    n = sum(r["frames"] for r in rs)
    return {"sequences": len(rs), "frames": int(sum(len(r["iou"]) for r in rs)),
            "AO_2d": float(np.mean([r["iou"].mean() for r in rs])),
            "SR_0.5": float(np.mean([(r["iou"] > 0.5).mean() for r in rs])),
            "SR_0.75": float(np.mean([(r["iou"] > 0.75).mean() for r in rs])),
            "ACE_2d": float(np.mean([r["ce"].mean() for r in rs])),
            "fps_1t": n / t if t > 0 else float("nan"), "fps_1t_from_median": float(1e3 / np.median(frame_ms)),
            "ms_median_1t": float(np.median(frame_ms)), "ms_p90_1t": float(np.percentile(frame_ms, 90)),
            "success_curve": np.mean([[(r["iou"] > x).mean() for x in IOU_T] for r in rs], axis=0).tolist(),
            "precision_curve": np.mean([[(r["ce"] <= x).mean() for x in CE_T] for r in rs], axis=0).tolist()}


def sweep_specs(args) -> dict:
    """Edge design points: (model prefix, search size, scales) -> spec. Models: every
    siamfc_*_search.onnx in --sweep-models (plus its _int8 twin when present)."""
    specs = {}
    dirs = [Path(d) for d in args.sweep_models]
    prefixes = []
    for d in dirs:
        for p in sorted(d.glob("*_search.onnx")):
            prefixes.append(p.parent / p.name[: -len("_search.onnx")])
    for pre in prefixes:
        for n in args.sweep_sizes:
            for s in args.sweep_scales:
                specs[f"{pre.name}@{s}x{n}"] = {"model": str(pre), "options": {"instance_size": n, "scale_num": s},
                                               "prefix": pre.name, "instance_size": n, "scale_num": s}
    return specs


def ratio_ort_torch(threads_list) -> list[dict]:
    sys.path.insert(0, str(ROOT / "export"))
    import tempfile

    import torch

    from track3d_train.siamfc.export import export_onnx, time_backbone
    from track3d_train.siamfc.model import SiamFC, config_for

    out = []
    with tempfile.TemporaryDirectory() as d:
        for variant, s, n in (("faithful", 3, 255), ("edge", 1, 191)):
            torch.manual_seed(0)
            net = SiamFC(config_for(variant)).eval()
            _, px = export_onnx(net, Path(d) / variant)
            for th in threads_list:
                pin(th)
                r = time_backbone(net, px, s, n, threads=th, repeats=20)
                r["variant"] = variant
                out.append(r)
                print(f"  ratio {variant} {s}x{n} {th}t: torch {r['torch_ms']:.1f} ms, ort {r['ort_ms']:.1f} ms, "
                      f"torch/ort {r['ratio_torch_over_ort']:.2f}", flush=True)
    return out


def plots(results: dict, out: Path, sweep: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for kind, xs, key, xl, fn in (("success", IOU_T, "success_curve", "IoU threshold", "bench_2d_success.png"),
                                  ("precision", CE_T, "precision_curve", "centre error threshold (px)",
                                   "bench_2d_precision.png")):
        fig, ax = plt.subplots(figsize=(6, 4.5))
        items = sorted(results.items(), key=lambda kv: -kv[1].get("AO_2d" if kind == "success" else "SR_0.5", 0))
        for name, r in items:
            if key not in r:
                continue
            lab = (f"{name} [AO {r['AO_2d']:.3f}]" if kind == "success"
                   else f"{name} [{np.interp(20, CE_T, r[key]):.3f} @20px]")
            ax.plot(xs, r[key], label=lab)
        ax.set_xlabel(xl)
        ax.set_ylabel("success rate" if kind == "success" else "precision")
        ax.set_title(f"{kind} plot, OPE on the test split")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / fn, dpi=110)
        plt.close(fig)
    if sweep:
        fig, ax = plt.subplots(figsize=(7, 5))
        groups = {}
        for name, r in sweep.items():
            groups.setdefault(r["prefix"], []).append(r)
        for g, rs in sorted(groups.items()):
            rs = sorted(rs, key=lambda r: r["ms_median_1t"])
            ax.plot([r["ms_median_1t"] for r in rs], [r["AO_2d"] for r in rs], "o-", label=g, alpha=0.8)
            for r in rs:
                ax.annotate(f"{r['scale_num']}x{r['instance_size']}", (r["ms_median_1t"], r["AO_2d"]), fontsize=7)
        ax.axvline(1000 / 100, color="grey", ls=":", lw=1)
        ax.text(1000 / 100, ax.get_ylim()[0], " whole 3D loop budget\n at 100 FPS", fontsize=7, va="bottom")
        ax.set_xscale("log")
        ax.set_xlabel("2D tracker ms / frame (median, 1 thread, pinned)")
        ax.set_ylabel("AO_2d (test split)")
        ax.set_title("SiamFC design: accuracy vs speed")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "bench_2d_tradeoff.png", dpi=110)
        plt.close(fig)


def table(results: dict, speed2: dict) -> str:
    lines = ["| tracker | AO_2d | SR@0.5 | ACE_2d (px) | FPS 1 thread | FPS 2 threads | FPS 1 thread (same subset) |",
             "|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        s2 = speed2.get(name, {})
        lines.append(f"| {name} | {r['AO_2d']:.3f} | {r['SR_0.5']:.3f} | {r['ACE_2d']:.1f} | {r['fps_1t']:.1f} | "
                     f"{s2.get('fps_2t', float('nan')):.1f} | {s2.get('fps_1t_subset', float('nan')):.1f} |")
    for name, r in PAPER.items():
        lines.append(f"| {name} | {r['AO_2d']:.3f} | - | {r['ACE_2d']:.1f} | {r['fps']:.1f} (GPU) | - | - |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(ROOT / "data" / "small"))
    ap.add_argument("--split", default="test")
    ap.add_argument("--trackers", default=",".join(DEFAULT_TRACKERS))
    ap.add_argument("--max-seqs", type=int, default=0, help="0: all")
    ap.add_argument("--speed-seqs", type=int, default=3, help="sequences for the 2-thread timing")
    ap.add_argument("--sweep", action="store_true", help="also run the edge design sweep")
    ap.add_argument("--sweep-models", nargs="*", default=[], help="folders with <name>_search.onnx")
    ap.add_argument("--sweep-sizes", type=int, nargs="*", default=[143, 159, 191, 255])
    ap.add_argument("--sweep-scales", type=int, nargs="*", default=[1, 3])
    ap.add_argument("--ratio", action="store_true", help="onnxruntime vs torch eager (needs torch)")
    ap.add_argument("--out", default=str(RESULTS))
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    ds = Dataset(a.data)
    seqs = ds.sequences(a.split)[: a.max_seqs or None]
    names = [t for t in a.trackers.split(",") if t]
    factories, skipped = {}, {}
    for n in names:
        try:
            f = make_factory(n)
            f(1)  # fail early when a model is missing
            factories[n] = f
        except Exception as e:
            skipped[n] = f"{type(e).__name__}: {e}"
            print(f"skip {n}: {skipped[n]}", flush=True)
    sweep = sweep_specs(a) if a.sweep else {}
    sweep_f = {k: make_factory("siamfc", v) for k, v in sweep.items()}
    per = {n: [] for n in list(factories) + list(sweep_f)}
    speed = {n: {"t1": 0.0, "t2": 0.0, "n": 0} for n in factories}
    t_start = time.perf_counter()
    load_before = os.getloadavg()
    for si, seq in enumerate(seqs):
        frames = np.stack([seq.image(i) for i in range(len(seq))])
        gt = seq.gt2d
        valid = (~seq.absent) & np.all(np.isfinite(gt), axis=1) & (gt[:, 2] > 0) & (gt[:, 3] > 0)
        if valid.sum() < 2:
            continue
        pin(1)
        for n, f in list(factories.items()) + list(sweep_f.items()):
            r = run_one(f(1), frames, gt, valid)
            per[n].append(r)
            if n in speed and si < a.speed_seqs:
                speed[n]["t1"] += r["time_s"]
                speed[n]["n"] += r["frames"]
        if si < a.speed_seqs:
            pin(2)
            for n, f in factories.items():
                speed[n]["t2"] += run_one(f(2), frames, gt, valid)["time_s"]
            pin(1)
        done = {n: np.mean([x["iou"].mean() for x in per[n] if len(x["iou"])]) for n in factories}
        print(f"[{si + 1}/{len(seqs)}] {seq.name} {time.perf_counter() - t_start:.0f}s  " +
              "  ".join(f"{n} {v:.3f}" for n, v in done.items()), flush=True)
    results = {n: summarise(per[n]) for n in factories}
    speed2 = {n: {"fps_2t": s["n"] / s["t2"] if s["t2"] else float("nan"),
                  "fps_1t_subset": s["n"] / s["t1"] if s["t1"] else float("nan"), "frames": s["n"]}
              for n, s in speed.items()}
    for n in results:
        results[n]["fps_2t"] = speed2[n]["fps_2t"]
        results[n]["fps_1t_subset"] = speed2[n]["fps_1t_subset"]
    sweep_res = {}
    for k, v in sweep.items():
        r = summarise(per[k])
        r.pop("success_curve", None)
        r.pop("precision_curve", None)
        sweep_res[k] = {**r, **{kk: v[kk] for kk in ("prefix", "instance_size", "scale_num")}}
    ratio = ratio_ort_torch([1, 2]) if a.ratio else []
    pin(2)
    meta = {}
    for n in factories:
        if n.startswith("siamfc"):
            tr = factories[n](1)
            meta[n] = {"instance_size": tr.instance_size, "scale_num": tr.scale_num,
                       "channels": tr.meta.get("channels"), "training": tr.meta.get("training")}
    import onnxruntime
    rec = {"cpu": cpu_model(), "machine": platform.machine(), "python": platform.python_version(),
           "onnxruntime": onnxruntime.__version__, "opencv": cv2.__version__,
           "data": str(Path(a.data).resolve()), "split": a.split, "sequences": len(seqs),
           "protocol": "OPE, init on the first present frame, no restart, absent frames not scored; "
                       "FPS = tracker update time only (frames preloaded); 1 thread pinned to one core",
           "trackers": results, "siamfc_models": meta, "skipped": skipped, "sweep": sweep_res,
           "ort_vs_torch": ratio, "paper": PAPER, "wall_s": time.perf_counter() - t_start,
           "loadavg_before": load_before, "loadavg_after": os.getloadavg(),
           "note": "the 2 cores are shared with other jobs: timings are noisy; medians are more robust",
           "date": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}
    (out / "bench_2d.json").write_text(json.dumps(rec, indent=1))
    md = table(results, speed2)
    if sweep_res:
        md += "\n\n| design | AO_2d | SR@0.5 | ms/frame (median, 1t) | FPS 1t |\n|---|---|---|---|---|\n"
        md += "\n".join(f"| {k} | {r['AO_2d']:.3f} | {r['SR_0.5']:.3f} | {r['ms_median_1t']:.2f} | {r['fps_1t']:.0f} |"
                        for k, r in sorted(sweep_res.items(), key=lambda kv: kv[1]["ms_median_1t"]))
    if ratio:
        md += "\n\n| search graph | threads | torch eager ms | onnxruntime ms | torch / ORT |\n|---|---|---|---|---|\n"
        md += "\n".join(f"| {r['variant']} {r['scales']}x{r['size']} | {r['threads']} | {r['torch_ms']:.1f} | "
                        f"{r['ort_ms']:.1f} | {r['ratio_torch_over_ort']:.2f} |" for r in ratio)
    (out / "bench_2d.md").write_text(f"CPU: {rec['cpu']}\n\n" + md + "\n")
    try:
        plots(results, out, sweep_res)
    except ImportError as e:
        print(f"no plots: {e}")
    print(md)
    return 0


if __name__ == "__main__":
    from track3d.argparsing import run_main

    sys.exit(run_main(main, "bench_2d.py"))
