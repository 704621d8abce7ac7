"""Edge FPS benchmark of the full Track3D loop.

Runs the loop over preloaded frames of a dataset split (I/O excluded), re-initialising from the
ground truth at each sequence start, for at least --frames frames per configuration, and reports
per stage (image crop, 2D network, 2D post-processing, frustum, box-net sampling/decoding, box
network, fusion, Python overhead) and end to end: median, p99 and mean in milliseconds, FPS.
With --threads 1 every thread of the process is pinned to ONE core (sched_setaffinity on each
task), which is the project's target ("100 FPS on one core"); with 2 it may use both.

    python benchmarks/bench_fps.py --data data/small --frames 1000 --threads 1 2 --torch --int8

--torch: every configuration with a SiamFC and/or A3BoxNet also runs, right after its
onnxruntime run, with the SAME networks (same weights, loaded from the training checkpoints)
executed by torch eager (torch.inference_mode, torch.set_num_threads(threads)); the torch
outputs are checked against onnxruntime on the first call of each network (1e-3 relative),
and each torch row reports ORT/torch FPS for net2d, net3d and end to end. torch is imported
only here and only with --torch: the runtime never imports it.
--int8: also the configurations whose SiamFC uses the int8 graphs (<prefix>_int8_*.onnx),
labelled e.g. siamfc-edge-int8.

Writes <out-dir>/fps_<tag>.json (machine, CPU model, versions, every configuration) and
fps_<tag>.md (the summary table, also printed).
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from track3d.dataset import Dataset
from track3d.onnxmodel import MODELS_DIR, OnnxModel
from track3d.tracker import Track3D

STAGES = ("crop", "net2d", "post2d", "frustum", "boxnet_other", "net3d", "fusion", "overhead", "end_to_end")
ROOT = Path(__file__).resolve().parents[1]
# Benchmarks never write into the repository unless asked: by default their output goes to
# ./bench-results under the current folder; pass --out benchmarks/results/... to update the committed files.
OUT_ROOT = Path("bench-results")
RESULTS = OUT_ROOT
SIAMFC_STEMS = {"siamfc-edge": "siamfc_edge", "siamfc": "siamfc_faithful"}  # tracker name -> shipped stem
RATIO_STAGES = ("net2d", "net3d", "end_to_end")
EQUIV_RTOL = 1e-3
UNAVAILABLE = ("TrackerUnavailable", "EstimatorUnavailable", "ModelError")  # a missing model: skipped, not failed


from track3d.machine import affinity_of_all_threads, pin  # noqa: E402  (one implementation)
from track3d.machine import cpu_name as cpu_model, isa_flags  # noqa: E402


class EquivalenceError(RuntimeError):
    """torch and onnxruntime disagree on the same inputs."""


class TorchModel:
    """Stand-in for an OnnxModel: the same ``run(feeds, outputs)``, ``meta``, ``input_names``,
    ``output_names``, ``path``, executed by a torch module (the wrapper that export.py exports,
    so inputs and outputs are the ONNX graph's, in order). On its first call it also runs the
    onnxruntime model it replaces on the same feeds and raises EquivalenceError beyond
    EQUIV_RTOL (max |torch - ort| / max |ort|, per output); the result is kept in ``check``."""

    def __init__(self, torch, module, ref: OnnxModel, checkpoint: Path):
        self._torch = torch
        self.module = module.eval()
        self.meta = ref.meta
        self.input_names = list(ref.input_names)
        self.output_names = list(ref.output_names)
        self.path = Path(checkpoint)
        self._ref: OnnxModel | None = ref
        self.check: dict | None = None

    def run(self, feeds: dict[str, np.ndarray], outputs: list[str] | None = None) -> list[np.ndarray]:
        torch = self._torch
        args = [torch.from_numpy(np.ascontiguousarray(feeds[n])) for n in self.input_names]
        with torch.inference_mode():
            out = self.module(*args)
        if isinstance(out, torch.Tensor):
            out = (out,)
        got = dict(zip(self.output_names, (o.numpy() for o in out)))
        res = [got[n] for n in (outputs or self.output_names)]
        if self._ref is not None:
            self._compare(feeds, outputs, res)
        return res

    def _compare(self, feeds, outputs, res) -> None:
        ref, self._ref = self._ref, None  # once; drop the session
        names = list(outputs or self.output_names)
        want = ref.run(feeds, names)
        self.check = {"kind": self.meta.get("kind"), "rtol": EQUIV_RTOL, "outputs": {}}
        bad = []
        for n, t, o in zip(names, res, want):
            if t.shape != o.shape:
                bad.append(f"{n}: shape torch {t.shape} vs onnxruntime {o.shape}")
                self.check["outputs"][n] = {"shape_torch": list(t.shape), "shape_ort": list(o.shape)}
                continue
            d = float(np.max(np.abs(t.astype(np.float64) - o))) if t.size else 0.0
            scale = float(np.max(np.abs(o))) if o.size else 0.0
            rel = d / max(scale, 1e-12)
            self.check["outputs"][n] = {"max_abs": d, "max_rel": rel}
            if not rel <= EQUIV_RTOL:
                bad.append(f"{n}: max |diff| {d:.3g} = {rel:.2e} of max |ort| {scale:.3g}")
        self.check["ok"] = not bad
        if bad:
            raise EquivalenceError(f"torch vs onnxruntime ({self.meta.get('kind')}, {self.path}): "
                                   + "; ".join(bad) + " -- is this checkpoint the one the ONNX was exported from?")


class TorchNets:
    """Checkpoints -> torch modules (the exported wrappers), loaded once, keyed by ONNX kind."""

    def __init__(self, siamfc: dict[str, Path], boxnet: Path):
        import torch

        self.torch = torch
        self.siamfc_ckpt = siamfc  # tracker name -> checkpoint
        self.boxnet_ckpt = boxnet
        self._cache: dict[Path, dict] = {}

    def needed(self, tracker: str, estimator: str) -> dict[str, Path]:
        """{role: checkpoint} this configuration needs ('2d', '3d'); empty: no network."""
        need = {}
        if tracker in self.siamfc_ckpt:
            need["2d"] = self.siamfc_ckpt[tracker]
        if estimator == "a3boxnet":
            need["3d"] = self.boxnet_ckpt
        return need

    def modules(self, ckpt: Path, role: str) -> dict:
        ckpt = Path(ckpt)
        if ckpt not in self._cache:
            if role == "2d":
                from track3d_train.siamfc.export import ExemplarGraph, SearchGraph
                from track3d_train.siamfc.train import load_checkpoint

                net, _ = load_checkpoint(ckpt)
                net.eval()
                self._cache[ckpt] = {"siamfc-exemplar": ExemplarGraph(net).eval(),
                                     "siamfc-search": SearchGraph(net).eval()}
            else:
                from track3d_train.boxnet.train import load_checkpoint

                model, _ = load_checkpoint(ckpt)  # A3BoxNet is exported as is
                self._cache[ckpt] = {"a3boxnet": model.eval()}
        return self._cache[ckpt]

    def swap(self, obj, ckpt: Path, role: str) -> list[TorchModel]:
        """Replace the OnnxModel attributes of a tracker / estimator by TorchModels."""
        mods = self.modules(ckpt, role)
        swapped = []
        for name, v in list(vars(obj).items()):
            if isinstance(v, OnnxModel) and v.meta.get("kind") in mods:
                tm = TorchModel(self.torch, mods[v.meta["kind"]], v, ckpt)
                setattr(obj, name, tm)
                swapped.append(tm)
        if not swapped:
            raise RuntimeError(f"{type(obj).__name__} holds no onnxruntime model of kind {sorted(mods)}")
        return swapped


def _onnx_models(obj, depth: int = 2):
    """The OnnxModel / TorchModel instances held by a tracker or estimator (one or two levels)."""
    found = []
    for v in vars(obj).values() if hasattr(obj, "__dict__") else ():
        if isinstance(v, (OnnxModel, TorchModel)):
            found.append(v)
        elif depth > 1 and hasattr(v, "__dict__") and not isinstance(v, (np.ndarray, type)):
            found.extend(_onnx_models(v, depth - 1))
    return found


class _Timer:
    """Accumulates the wall time of wrapped model.run calls between two reads."""

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


def build(camera, cfg: dict, threads: int, fusion: bool = True) -> Track3D:
    topt = {"threads": threads, **cfg.get("tracker_options", {})}
    eopt = {"threads": threads, **cfg.get("estimator_options", {})}
    try:
        return Track3D.create(camera, cfg["tracker"], cfg["estimator"], tracker_options=topt,
                              estimator_options=eopt, fusion=fusion)
    except TypeError:  # classic OpenCV trackers take no thread count (cv2.setNumThreads is global)
        import cv2
        cv2.setNumThreads(threads)
        topt.pop("threads")
        return Track3D.create(camera, cfg["tracker"], cfg["estimator"], tracker_options=topt,
                              estimator_options=eopt, fusion=fusion)


def run_config(camera, sequences, cfg: dict, threads: int, frames: int, fusion: bool = True,
               torch_nets: TorchNets | None = None):
    t3d = build(camera, cfg, threads, fusion)
    swapped: list[TorchModel] = []
    if cfg["backend"] == "torch":
        torch_nets.torch.set_num_threads(threads)
        for role, ckpt in cfg["checkpoints"].items():
            swapped += torch_nets.swap(t3d.tracker2d if role == "2d" else t3d.estimator, ckpt, role)
    net2d = _Timer(_onnx_models(t3d.tracker2d))
    net3d = _Timer(_onnx_models(t3d.estimator))
    rows = {k: [] for k in STAGES}
    statuses: dict[str, int] = {}
    done = 0
    warm = 20  # the torch/ORT equivalence checks happen here (init and the first updates)
    cpu0 = wall0 = None
    while done < frames + warm:
        progressed = False
        for seq, fr in sequences:
            first = next((k for k in range(len(fr)) if not seq.absent[k] and fr[k][2][2] > 0), None)
            if first is None:
                continue
            img, pts, box = fr[first]
            t3d.init(img, box, seq.category, points=pts)
            net2d.take(), net3d.take()
            for img, pts, _ in fr[first + 1:]:
                progressed = True
                t = time.perf_counter()
                res = t3d.update(img, pts)
                e2e = (time.perf_counter() - t) * 1e3
                n2, n3 = net2d.take(), net3d.take()
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
    unchecked = [m.meta.get("kind") for m in swapped if m.check is None]
    if unchecked:
        raise EquivalenceError(f"torch model(s) {unchecked} never ran during warm-up: equivalence not checked")
    stats = {k: {"median_ms": float(np.median(v)), "p99_ms": float(np.percentile(v, 99)),
                 "mean_ms": float(np.mean(v))} for k, v in rows.items()}
    e2e = np.asarray(rows["end_to_end"])
    out = {"config": cfg["label"], "tracker": cfg["tracker"], "estimator": cfg["estimator"],
           "backend": cfg["backend"], "precision": cfg["precision"], "threads": threads, "fusion": fusion,
           "frames": int(len(e2e)), "fps_median": float(1e3 / np.median(e2e)),
           "fps_mean": float(1e3 / np.mean(e2e)), "statuses": statuses, "stages": stats,
           "cpus_allowed": affinity_of_all_threads(), "process_threads": len(os.listdir("/proc/self/task")),
           "cpu_utilisation": cpu_s / max(wall_s, 1e-9),
           "models": {"tracker_options": {k: str(v) for k, v in cfg.get("tracker_options", {}).items()},
                      "estimator_options": {k: str(v) for k, v in cfg.get("estimator_options", {}).items()}}}
    if cfg["backend"] == "torch":
        out["torch_threads"] = torch_nets.torch.get_num_threads()
        out["checkpoints"] = {k: str(v) for k, v in cfg["checkpoints"].items()}
        out["equivalence"] = [m.check for m in swapped]
    return out


def make_configs(args, torch_nets: TorchNets | None) -> tuple[list[dict], list[dict]]:
    """(configurations to run, skipped {config, reason}) in run order: each ORT fp32
    configuration, then its torch twin, then its int8 twin."""
    prefixes = {"siamfc-edge": args.siamfc_edge_model, "siamfc": args.siamfc_model}
    pairs = [c.split(":") for c in (args.config or ["siamfc-edge:a3boxnet", "siamfc:a3boxnet", "kcf:baseline"])]
    configs, skipped = [], []
    for pair in pairs:
        if len(pair) != 2:
            raise SystemExit(f"--config takes TRACKER:ESTIMATOR, got {':'.join(pair)!r}")
        tracker, estimator = pair
        topt, eopt = {}, {}
        if tracker in prefixes and prefixes[tracker] is not None:
            topt["model"] = str(prefixes[tracker])
        if estimator == "a3boxnet" and args.boxnet_model is not None:
            eopt["model"] = str(args.boxnet_model)
        base = {"label": f"{tracker}:{estimator}", "tracker": tracker, "estimator": estimator,
                "tracker_options": topt, "estimator_options": eopt, "backend": "onnxruntime", "precision": "fp32"}
        configs.append(base)
        if torch_nets is not None:
            need = torch_nets.needed(tracker, estimator)
            missing = [f"{r} checkpoint {p}" for r, p in need.items() if not Path(p).is_file()]
            if not need:
                pass  # no network to run in torch (e.g. kcf:baseline)
            elif missing:
                skipped.append({"config": base["label"], "backend": "torch",
                                "reason": "missing " + ", ".join(missing)})
            else:
                configs.append({**base, "backend": "torch", "checkpoints": need})
        if args.int8 and tracker in SIAMFC_STEMS:
            fp32 = Path(prefixes[tracker]) if prefixes[tracker] is not None else MODELS_DIR / SIAMFC_STEMS[tracker]
            stem = fp32.name
            for suffix in ("_exemplar.onnx", "_search.onnx", ".onnx"):  # as track3d.siamfc.create
                if stem.endswith(suffix):
                    stem = stem[: -len(suffix)]
                    break
            q = fp32.parent / f"{stem}_int8"
            files = [q.parent / f"{q.name}_exemplar.onnx", q.parent / f"{q.name}_search.onnx"]
            label = f"{tracker}-int8:{estimator}"
            missing = [str(f) for f in files if not f.is_file()]
            if missing:
                skipped.append({"config": label, "backend": "onnxruntime", "reason": "missing " + ", ".join(missing)})
            else:
                configs.append({**base, "label": label, "precision": "int8",
                                "tracker_options": {**topt, "model": str(q)}})
    return configs, skipped


def add_ratios(results: list[dict]) -> None:
    """torch rows: ORT/torch FPS (= torch ms / ORT ms, medians) of the matching ORT fp32 row;
    int8 rows: fp32/int8 ms (the int8 speed-up) of the matching fp32 ORT row."""
    ort = {(r["config"], r["threads"]): r for r in results
           if r["backend"] == "onnxruntime" and r["precision"] == "fp32"}
    for r in results:
        if r["backend"] == "torch":
            ref = ort.get((r["config"], r["threads"]))
            key = "ort_over_torch_fps"
        elif r["precision"] == "int8":
            ref = ort.get((f"{r['tracker']}:{r['estimator']}", r["threads"]))
            key = "int8_speedup_vs_fp32"
        else:
            continue
        if ref is None:
            r[key] = None
            continue
        ratio = {}
        for k in RATIO_STAGES:
            mine, theirs = r["stages"][k]["median_ms"], ref["stages"][k]["median_ms"]
            num, den = (mine, theirs) if r["backend"] == "torch" else (theirs, mine)
            ratio[k] = num / den if den > 0 else None
        r[key] = ratio


def _f(v, fmt="{:.2f}") -> str:
    return "—" if v is None else fmt.format(v)


def markdown(out: dict) -> str:
    lines = [f"FPS benchmark, {out['cpu']} ({out['logical_cpus']} logical CPUs), onnxruntime "
             f"{out['onnxruntime']}" + (f", torch {out['torch']}" if out.get("torch") else "")
             + f"; medians over {out['frames_requested']} frames; ms",
             "",
             "| config | backend | precision | threads | e2e median ms | p99 | FPS | net2d | net3d | ratio |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in out["results"]:
        s = r["stages"]
        if r.get("ort_over_torch_fps"):
            q = r["ort_over_torch_fps"]
            ratio = f"ORT/torch FPS: e2e {_f(q['end_to_end'])}, net2d {_f(q['net2d'])}, net3d {_f(q['net3d'])}"
        elif r.get("int8_speedup_vs_fp32"):
            q = r["int8_speedup_vs_fp32"]
            ratio = f"fp32/int8 ms: e2e {_f(q['end_to_end'])}, net2d {_f(q['net2d'])}"
        else:
            ratio = ""
        lines.append(f"| {r['config']} | {r['backend']} | {r['precision']} | {r['threads']} | "
                     f"{s['end_to_end']['median_ms']:.2f} | {s['end_to_end']['p99_ms']:.2f} | {r['fps_median']:.1f} | "
                     f"{s['net2d']['median_ms']:.2f} | {s['net3d']['median_ms']:.2f} | {ratio} |")
    if out["skipped"] or out["failed"]:
        lines.append("")
    for r in out["skipped"]:
        at = f", {r['threads']} threads" if "threads" in r else ""
        lines.append(f"- skipped {r['config']} ({r['backend']}{at}): {r['reason']}")
    for r in out["failed"]:
        lines.append(f"- FAILED {r['config']} ({r['backend']}, {r['threads']} threads): {r['reason']}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="dataset root (track3d-sim output)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--frames", type=int, default=1000, help="measured frames per configuration (>= 1000 for p99)")
    ap.add_argument("--preload", type=int, default=400, help="frames kept in memory (looped over)")
    ap.add_argument("--sequences", type=int, default=8)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--config", action="append", default=None, metavar="TRACKER:ESTIMATOR",
                    help="configurations to run (default: siamfc-edge:a3boxnet siamfc:a3boxnet kcf:baseline)")
    ap.add_argument("--tag", default=None, help="result file name tag (default: the host name)")
    ap.add_argument("--out-dir", type=Path, default=RESULTS, help="where fps_<tag>.json/.md go (default: %(default)s)")
    ap.add_argument("--siamfc-edge-model", type=Path, default=None, metavar="PREFIX",
                    help="<dir>/<name> of a non-shipped <name>_exemplar.onnx/_search.onnx pair for siamfc-edge")
    ap.add_argument("--siamfc-model", type=Path, default=None, metavar="PREFIX",
                    help="the same for siamfc (faithful)")
    ap.add_argument("--boxnet-model", type=Path, default=None, metavar="ONNX", help="a non-shipped A3BoxNet ONNX")
    ap.add_argument("--int8", action="store_true",
                    help="also run SiamFC from <prefix>_int8_exemplar/_search.onnx (shipped: models/siamfc_edge_int8_*)")
    ap.add_argument("--torch", action="store_true",
                    help="also run every SiamFC / A3BoxNet configuration in torch eager")
    ap.add_argument("--torch-siamfc-edge", type=Path, default=ROOT / "runs/siamfc_edge/ckpt.pt", metavar="CKPT")
    ap.add_argument("--torch-siamfc", type=Path, default=ROOT / "runs/siamfc_faithful/ckpt.pt", metavar="CKPT")
    ap.add_argument("--torch-boxnet", type=Path, default=ROOT / "runs/boxnet/main/best.pt", metavar="CKPT")
    args = ap.parse_args(argv)
    torch_nets = None
    if args.torch:
        torch_nets = TorchNets({"siamfc-edge": args.torch_siamfc_edge, "siamfc": args.torch_siamfc}, args.torch_boxnet)
    configs, skipped = make_configs(args, torch_nets)
    for s in skipped:
        print(f"skip {s['config']} ({s['backend']}): {s['reason']}", file=sys.stderr)
    camera, seqs = load_frames(args.data, args.split, args.preload, args.sequences)
    print(f"preloaded {sum(len(f) for _, f in seqs)} frames of {len(seqs)} sequences", file=sys.stderr)
    all_cpus = os.sched_getaffinity(0)
    results, failed = [], []
    for threads in args.threads:
        pin({min(all_cpus)} if threads == 1 else all_cpus)
        for cfg in configs:
            try:
                r = run_config(camera, seqs, cfg, threads, args.frames, torch_nets=torch_nets)
            except Exception as e:  # a missing model or a failed check must not lose the other configurations
                kind = "skip" if type(e).__name__ in UNAVAILABLE else "FAILED"
                print(f"{kind} {cfg['label']} ({cfg['backend']}) @ {threads} threads: {type(e).__name__}: {e}",
                      file=sys.stderr)
                (failed if kind == "FAILED" else skipped).append(
                    {"config": cfg["label"], "backend": cfg["backend"], "threads": threads,
                     "reason": f"{type(e).__name__}: {e}"})
                continue
            finally:
                gc.collect()  # each model's run is wrapped in a closure (a cycle): free its sessions now
            results.append(r)
            s = r["stages"]
            print(f"{cfg['label']:24s} {cfg['backend']:11s} {cfg['precision']} threads={threads} "
                  f"fps(median)={r['fps_median']:7.1f} e2e median={s['end_to_end']['median_ms']:.2f} "
                  f"p99={s['end_to_end']['p99_ms']:.2f} ms | "
                  + " ".join(f"{k}={s[k]['median_ms']:.2f}" for k in STAGES[:-1]), flush=True)
    pin(all_cpus)
    add_ratios(results)
    import cv2
    import onnxruntime
    out = {"benchmark": "track3d end-to-end FPS", "cpu": cpu_model(), "isa_flags": isa_flags(), "machine": platform.node(),
           "logical_cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
           "onnxruntime": onnxruntime.__version__, "opencv": cv2.__version__,
           "torch": torch_nets.torch.__version__ if torch_nets else None,
           "data": str(args.data), "split": args.split, "frames_requested": args.frames,
           "note": "I/O excluded; threads=1 runs pinned to one core (every thread); "
                   "ort_over_torch_fps = torch median ms / onnxruntime median ms of the same configuration "
                   "(> 1: onnxruntime faster); int8_speedup_vs_fp32 = fp32 median ms / int8 median ms",
           "results": results, "skipped": skipped, "failed": failed}
    args.out_dir.mkdir(parents=True, exist_ok=True)
    tag = args.tag or platform.node()
    path = args.out_dir / f"fps_{tag}.json"
    path.write_text(json.dumps(out, indent=2))
    md = markdown(out)
    (args.out_dir / f"fps_{tag}.md").write_text(md)
    print(md)
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 1 if failed else 0


if __name__ == "__main__":
    from track3d.argparsing import run_main

    sys.exit(run_main(main, "bench_fps.py"))
