"""Every engine x precision side by side: per network and for the whole Track3D loop.

    python benchmarks/bench_precision.py --data data/small --frames 300 --rounds 3

Per network (A3BoxNet at its N points, SiamFC-edge search at its instance size with one scale,
SiamFC-edge exemplar): each available variant (onnxruntime fp32 / int8, OpenVINO fp32 / bf16;
OpenVINO does not run the int8 files, see track3d.onnxmodel) on the same fixed random inputs, all variants run ROUND-ROBIN for --net-seconds (so that
other load on the machine hits them alike), each call after track3d.variant_choice.GAP_S of other
work as in the loop (what precision="auto" measures; files from before that timed calls back to
back), median ms; max relative difference to onnxruntime
fp32 (max |diff| / max |fp32| over the outputs).

Whole loop (--tracker, default the default loop's edgetrack, + a3boxnet, fusion on, bench_fps's loop and stage timers on preloaded
frames, one thread pinned to one core): one configuration per variant (both networks at that
engine / precision) plus precision=auto / engine=auto, interleaved: --rounds rounds, each
running every configuration for frames/rounds frames; the reported ms is the median of the
rounds' medians. Ratios are to onnxruntime fp32 of the same run (> 1: faster).

Each network row names the file timed (e.g. "a3boxnet (a3boxnet_views.onnx)", --boxnet-model).
Every argument, --data and --accuracy-data included, is checked before any timing (one line,
exit 2).

Writes <out-dir>/precision_<tag>.json (CPU name, ISA flags, versions, every number) and .md.
"""
from __future__ import annotations

import gc
import json
import platform
import sys
from pathlib import Path

import numpy as np
from benchlib.loop_timing import build, load_frames, require_trackable, time_loop
from benchlib.output import add_out_argument, out_dir_problem
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, hidden_alias, run_main
from track3d.jsonable import write_json
from track3d.machine import START_CPUS, pin_threads
from track3d.boxnet import DEFAULT_MODEL
from track3d.onnxmodel import MODELS_DIR, ModelError, OnnxModel, openvino_version, variant_path
from track3d.variant_choice import example_feeds, measure

VARIANTS = (("onnxruntime", "fp32"), ("onnxruntime", "int8"), ("openvino", "fp32"), ("openvino", "bf16"))
# the 2D networks measured one by one (with the box network, --boxnet-model)
NETWORKS_2D = {"edgetrack_search": "edgetrack_search.onnx",
            "edgetrack_template": "edgetrack_template.onnx", "siamfc_edge_search": "siamfc_edge_search.onnx",
            "siamfc_edge_exemplar": "siamfc_edge_exemplar.onnx"}
# the files of each 2D tracker's networks (the search one first) and of the box net
TRACKER_FILES = {"edgetrack": ["edgetrack_search.onnx", "edgetrack_template.onnx"],
                 "siamfc-edge": ["siamfc_edge_search.onnx", "siamfc_edge_exemplar.onnx"],
                 "siamfc": ["siamfc_faithful_search.onnx", "siamfc_faithful_exemplar.onnx"]}
STAGES = ("net2d", "net3d", "end_to_end")


def label(v) -> str:
    return f"{v[0]}/{v[1]}"


def available(path: Path) -> tuple[dict, list[str]]:
    """{variant: OnnxModel} that load here; [why the others do not]."""
    models, skipped = {}, []
    for v in VARIANTS:
        if v[1] == "int8" and not variant_path(path, "int8").is_file():
            skipped.append(f"{label(v)}: no int8 file")
            continue
        try:
            models[v] = OnnxModel(path, threads=1, engine=v[0], precision=v[1])
        except ModelError as e:
            skipped.append(f"{label(v)}: {e}")
    return models, skipped


def bench_networks(seconds: float, boxnet: str = DEFAULT_MODEL) -> dict:
    out = {}
    for name, file in {"a3boxnet": boxnet, **NETWORKS_2D}.items():
        path = MODELS_DIR / file
        models, skipped = available(path)
        ref = models[("onnxruntime", "fp32")]
        feeds = example_feeds(path, ref.meta)
        want = ref.run(feeds)
        diffs = {}
        for v, m in models.items():
            got = m.run(feeds)
            diffs[v] = max(float(np.abs(g.astype(np.float64) - w).max() / max(np.abs(w).max(), 1e-12))
                           for g, w in zip(got, want))
        ms = measure(models, feeds, seconds)
        base = ms[("onnxruntime", "fp32")]
        out[name] = {"file": path.name, "inputs": {k: list(v.shape) for k, v in feeds.items()}, "skipped": skipped,
                     "variants": {label(v): {"median_ms": ms[v], "speedup_vs_ort_fp32": base / ms[v],
                                             "max_rel_diff_vs_ort_fp32": diffs[v]} for v in models}}
        print(f"{network_label(name, path.name)}: " + ", ".join(f"{label(v)} {ms[v]:.2f} ms (x{base / ms[v]:.2f}, rel {diffs[v]:.1e})"
                                      for v in models), flush=True)
        del models
        gc.collect()
    return out


def network_label(name: str, file: str | None) -> str:
    """A network row's name with the file timed when the name does not say it: always for the box
    network ("a3boxnet" is the views model by default, the full-width one with --boxnet-model
    a3boxnet.onnx, ...)."""
    return f"{name} ({file})" if file and (name == "a3boxnet" or Path(file).stem != name) else name


def loop_configs(tracker: str = "edgetrack", boxnet: str = DEFAULT_MODEL) -> list[dict]:
    """One configuration per variant: each network at that engine / precision when it has it
    (else fp32 on that engine, said in the label), plus auto / auto."""
    cfgs = []
    for e, p in VARIANTS + (("auto", "auto"),):
        topt, eopt = {"precision": p, "engine": e}, {"precision": p, "engine": e, "model": boxnet}
        if p == "int8":
            if not variant_path(MODELS_DIR / TRACKER_FILES[tracker][0], "int8").is_file():
                topt["precision"] = "fp32"
            if not variant_path(MODELS_DIR / boxnet, "int8").is_file():
                eopt["precision"] = "fp32"
            if topt["precision"] == eopt["precision"] == "fp32":
                continue
        same = topt["precision"] == eopt["precision"]
        lab = f"{e}/{p}" if same else f"{e}: {tracker} {topt['precision']}, a3boxnet {eopt['precision']}"
        cfgs.append({"label": lab, "tracker": tracker, "estimator": "a3boxnet", "backend": e,
                     "precision": p, "tracker_options": topt, "estimator_options": eopt})
    return cfgs


def preload_loop_frames(data: Path, split: str, preload: int, sequences: int):
    """load_frames for the whole-loop rows, refusing (ValueError, one line) a split with no frame to
    track: checked before any timing (it had been found after the per-network timing, and every
    loop row then said "skipped")."""
    camera, seqs = load_frames(data, split, preload, sequences)
    require_trackable(seqs, f"{data} split {split!r}, first {preload} frames")
    return camera, seqs


def bench_loop(data: Path, split: str, frames: int, rounds: int, preload: int, sequences: int,
               tracker: str = "edgetrack", boxnet: str = DEFAULT_MODEL, preloaded=None) -> dict:
    """preloaded: (camera, sequences) of preload_loop_frames (else loaded here)."""
    camera, seqs = preloaded or preload_loop_frames(data, split, preload, sequences)
    per = max(frames // rounds, 20)
    runs: dict[str, list[dict]] = {}
    skipped = {}
    for r in range(rounds):
        for cfg in loop_configs(tracker, boxnet):
            if cfg["label"] in skipped:
                continue
            try:
                res = time_loop(build(camera, cfg, 1), seqs, per)
            except (ModelError, RuntimeError) as e:  # e.g. OpenVINO not installed (Tracker/EstimatorUnavailable)
                skipped[cfg["label"]] = str(e)
                continue
            finally:
                gc.collect()
            runs.setdefault(cfg["label"], []).append(res)
            s = res["stages"]
            print(f"round {r + 1}/{rounds} {cfg['label']:22s} e2e {s['end_to_end']['median_ms']:.2f} ms "
                  f"net2d {s['net2d']['median_ms']:.2f} net3d {s['net3d']['median_ms']:.2f}", flush=True)
    out = {}
    base = None
    for lab, rs in runs.items():
        med = {k: float(np.median([x["stages"][k]["median_ms"] for x in rs])) for k in STAGES}
        if lab == "onnxruntime/fp32":
            base = med
        out[lab] = {"median_ms": med, "rounds": len(rs), "frames_per_round": per,
                    "statuses": rs[-1]["statuses"]}
    for lab, row in out.items():
        row["speedup_vs_ort_fp32"] = {k: base[k] / row["median_ms"][k] if base and row["median_ms"][k] > 0 else None
                                      for k in STAGES}
    return {"tracker": tracker, "boxnet": boxnet, "configs": out, "skipped": skipped}


AO_TOL, ACE_TOL_M = 0.005, 0.01   # the shipping rule (docs/models.md, "Arithmetic")


def accuracy_configs(tracker: str = "edgetrack", boxnet: str = DEFAULT_MODEL) -> list[tuple[str, dict, dict]]:
    """(label, 2D tracker options, A3BoxNet options): fp32 first, then each variant of one
    network at a time and of both together; the box network is the shipped file `boxnet`."""
    fp32 = {"precision": "fp32", "engine": "onnxruntime"}
    out = [("onnxruntime/fp32", fp32, {**fp32, "model": boxnet})]
    for e, p in VARIANTS[1:]:
        v = {"precision": p, "engine": e}
        out += [(f"{e}/{p} {tracker} only", v, {**fp32, "model": boxnet}),
                (f"{e}/{p} a3boxnet only", fp32, {**v, "model": boxnet}), (f"{e}/{p} both", v, {**v, "model": boxnet})]
    return out


def bench_accuracy(data: Path, split: str, out_dir: Path, tracker: str = "edgetrack",
                   only: list[str] | None = None, boxnet: str = DEFAULT_MODEL) -> dict:
    """AO_3d / ACE_3d of Track3D (`tracker` + A3BoxNet of the shipped file `boxnet`) per variant,
    restart and one-pass rows, and whether each variant passes the rule against fp32."""
    import tempfile

    from track3d.estimators import EstimatorUnavailable
    from track3d.evaluation import Experiment, TrackerSpec
    from track3d.evaluation.metrics import average_scores
    from track3d.trackers2d import TrackerUnavailable

    rows: dict[str, dict] = {}
    # the runs' scratch lives in the system's temp folder: a run killed by a signal (SIGTERM skips
    # the context manager's cleanup) left a tmpXXXX folder in the (committed) results folder
    with tempfile.TemporaryDirectory(prefix="track3d-precision-") as tmp:
        for lab, topt, eopt in accuracy_configs(tracker, boxnet):
            if only and lab != "onnxruntime/fp32" and not any(lab.startswith(o) for o in only):
                continue
            name = lab.replace("/", "-").replace(" ", "_")
            spec = TrackerSpec(tracker, "a3boxnet", threads=1, tracker_options=topt, estimator_options=eopt,
                               name=name)
            try:
                spec.build(Experiment(data, split, tmp).sequences[0])
            except (ModelError, TrackerUnavailable, EstimatorUnavailable) as e:   # e.g. no int8 twin here
                rows[lab] = {"skipped": str(e)}
                continue
            row = {}
            for mode, restart in (("restart", True), ("one_pass", False)):
                exp = Experiment(data, split, Path(tmp) / mode, restart=restart)
                exp.run(spec, overlay=None, quiet=True)
                ov = average_scores(exp.score(name))
                row[mode] = {"ao_3d": float(ov.values["ao_3d"]), "ace_3d": float(ov.values["ace_3d"]),
                             "restarts": int(ov.restarts)}
            rows[lab] = row
            print(f"accuracy {lab:32s} " + " ".join(f"{m}: AO_3d {r['ao_3d']:.4f} ACE_3d {r['ace_3d']:.4f} m"
                                                     for m, r in row.items()), flush=True)
    ref = rows["onnxruntime/fp32"]
    for lab, row in rows.items():
        if "skipped" in row or lab == "onnxruntime/fp32":
            continue
        d = {m: {"d_ao_3d": row[m]["ao_3d"] - ref[m]["ao_3d"], "d_ace_3d": row[m]["ace_3d"] - ref[m]["ace_3d"]}
             for m in ("restart", "one_pass")}
        row["delta"] = d
        row["passes"] = all(v["d_ao_3d"] >= -AO_TOL and v["d_ace_3d"] <= ACE_TOL_M for v in d.values())
    from track3d.dataset import Dataset

    seqs = Dataset(data).sequences(split)
    return {"tracker": tracker, "boxnet": boxnet, "split": split, "sequences": len(seqs), "frames": int(sum(len(q) for q in seqs)),
            "rule": f"AO_3d >= fp32 - {AO_TOL}, ACE_3d <= fp32 + {ACE_TOL_M} m, restart and one-pass",
            "rows": rows}


def write_verdicts(accs: list[dict], models_dir: Path = MODELS_DIR) -> Path:
    """Merge the per-network verdicts of accuracy runs (one per split, same tracker) into
    <models_dir>/accuracy.json, the file precision="auto" reads (track3d.variant_choice.VERDICTS_FILE):
    a network's variant is allowed only if its "<network> only" row passed on EVERY split (on 9
    sequences a one-pass row can flip with a tiny numeric change: measured, both ways)."""
    from track3d.variant_choice import VERDICTS_FILE, verdict_files

    path = models_dir / VERDICTS_FILE
    data = json.loads(path.read_text()) if path.is_file() else {}
    data["rule"] = accs[0]["rule"] + (", on every split measured" if len(accs) > 1 else "")
    models = data.setdefault("models", {})
    merged: dict[tuple[str, str], dict] = {}
    files_of = dict(TRACKER_FILES)
    for acc in accs:
        if "boxnet" not in acc:
            # a run from before --boxnet-model measured the default of its day, which need not be
            # today's: its verdict would land on another model
            raise ValueError(f"the accuracy run of split {acc.get('split')!r} does not name its A3BoxNet file "
                             "(made before --boxnet-model): re-measure it")
        files_of["a3boxnet"] = [acc["boxnet"]]
        for lab, row in acc["rows"].items():
            if "passes" not in row or not lab.endswith(" only"):
                continue
            variant, net = lab[: -len(" only")].split(" ")
            net = "siamfc-edge" if net == "siamfc" and acc["tracker"] == "siamfc-edge" else net   # older labels
            m = merged.setdefault((variant, net), {"passes": True, "tracker": acc["tracker"], "splits": {}})
            m["passes"] = m["passes"] and bool(row["passes"])
            m["splits"][acc["split"]] = {
                "passes": bool(row["passes"]), "sequences": acc["sequences"], "frames": acc["frames"],
                "d_ao_3d": {k: round(v["d_ao_3d"], 5) for k, v in row["delta"].items()},
                "d_ace_3d_m": {k: round(v["d_ace_3d"], 5) for k, v in row["delta"].items()}}
    for (variant, net), verdict in merged.items():
        for f in files_of[net]:
            # bound to the files measured: a later model under the same name gets no verdict
            models.setdefault(f, {})[variant] = {**verdict, **verdict_files(models_dir / f, variant)}
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    return path


def markdown(res: dict) -> str:
    lines = [f"Precision benchmark, {res['cpu']} (ISA: {', '.join(res['machine']['isa'])}), onnxruntime "
             f"{res['machine']['versions']['onnxruntime']}, OpenVINO {res['openvino'] or 'not installed'}; 1 thread; medians, ms "
             f"(x = speed-up vs onnxruntime fp32 in the same run)", "",
             "| network | " + " | ".join(label(v) for v in VARIANTS) + " |", "|---" * (len(VARIANTS) + 1) + "|"]
    for name, r in res["networks"].items():
        cells = []
        for v in VARIANTS:
            c = r["variants"].get(label(v))
            cells.append("—" if c is None else f"{c['median_ms']:.2f} (x{c['speedup_vs_ort_fp32']:.2f}, "
                                               f"rel {c['max_rel_diff_vs_ort_fp32']:.1e})")
        lines.append(f"| {network_label(name, r.get('file'))} | " + " | ".join(cells) + " |")
    if res.get("loop"):
        lines += ["", f"| whole loop config ({res['loop']['tracker']} + {res['loop']['boxnet']}) | end-to-end ms | x | "
                      "net2d ms | net3d ms |", "|---|---|---|---|---|"]
        for lab, r in res["loop"]["configs"].items():
            m, x = r["median_ms"], r["speedup_vs_ort_fp32"]
            lines.append(f"| {lab} | {m['end_to_end']:.2f} | x{x['end_to_end']:.2f} | {m['net2d']:.2f} | "
                         f"{m['net3d']:.2f} |")
        for lab, why in res["loop"]["skipped"].items():
            lines.append(f"- skipped {lab}: {why}")
    for acc in res.get("accuracy") or []:
        lines += ["", f"Track3D ({acc['tracker']} + {acc.get('boxnet', 'the A3BoxNet default of its day')}) accuracy on {acc['sequences']} sequences / {acc['frames']} frames of "
                      f"'{acc['split']}'; rule: {acc['rule']}", "",
                  "| variant | AO_3d restart | ACE_3d restart (m) | AO_3d one-pass | ACE_3d one-pass (m) | passes |",
                  "|---|---|---|---|---|---|"]
        for lab, r in acc["rows"].items():
            if "skipped" in r:
                lines.append(f"| {lab} | skipped: {r['skipped']} |||||")
                continue
            a, b = r["restart"], r["one_pass"]
            lines.append(f"| {lab} | {a['ao_3d']:.4f} | {a['ace_3d']:.4f} | {b['ao_3d']:.4f} | {b['ace_3d']:.4f} | "
                         f"{'reference' if 'passes' not in r else ('yes' if r['passes'] else 'NO')} |")
    if res.get("auto"):
        lines += ["", "precision=auto / engine=auto picks:"]
        lines += [f"- {d['model']}: {d['engine']}/{d['precision']} — {d['reason']}" for d in res["auto"]]
    return "\n".join(lines) + "\n"


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, default=None, help="dataset root for the whole-loop rows (none: networks only)")
    ap.add_argument("--split", default="test", help="dataset split (default test)")
    ap.add_argument("--frames", type=bounded(int, 1), default=300, help="measured loop frames per configuration (default 300)")
    ap.add_argument("--rounds", type=bounded(int, 1), default=3, help="interleaved rounds of the loop configurations (default 3)")
    ap.add_argument("--preload", type=bounded(int, 2), default=200,
                    help="frames kept in memory (at least a first frame and one to track; default 200)")
    ap.add_argument("--sequences", type=bounded(int, 1), default=6, help="sequences preloaded (default 6)")
    ap.add_argument("--net-seconds", type=bounded(float, above=0), default=3.0,
                    help="round-robin seconds per network (default 3)")
    ap.add_argument("--accuracy-data", type=Path, default=None,
                    help="dataset root: also Track3D's AO_3d / ACE_3d per variant (restart and one-pass) "
                         "and the shipping rule (default: not measured)")
    ap.add_argument("--accuracy-split", nargs="+", default=["test"],
                    help="split(s) of --accuracy-data; a variant passes only on every one (default test)")
    ap.add_argument("--tracker", default="edgetrack", choices=list(TRACKER_FILES),
                    help="2D tracker of the loop and accuracy rows (default edgetrack, the default loop's)")
    hidden_alias(ap, "--accuracy-tracker", "tracker")
    ap.add_argument("--accuracy-variants", nargs="+", default=None, metavar="LABEL",
                    help="only the accuracy rows starting with these labels, e.g. onnxruntime/int8 (default: all)")
    ap.add_argument("--boxnet-model", default=DEFAULT_MODEL, metavar="FILE",
                    help=f"the shipped A3BoxNet file whose variants are measured (default {DEFAULT_MODEL}; "
                         "e.g. a3boxnet_narrow.onnx)")
    ap.add_argument("--write-verdicts", action="store_true",
                    help="merge the accuracy verdicts into runtime/track3d/models/accuracy.json (read by auto); "
                         "needs --accuracy-data (refused without it)")
    ap.add_argument("--no-speed", action="store_true", help="skip the speed rows (accuracy only)")
    ap.add_argument("--tag", default=None, help="result file tag (default: the host name)")
    add_out_argument(ap, flag="--out-dir")
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    # every argument before any timing: a bad --data had been found after the per-network timing,
    # --write-verdicts without --accuracy-data silently did nothing, a file as --out-dir failed at the end
    if a.write_verdicts and a.accuracy_data is None:
        ap.error("argument --write-verdicts: needs --accuracy-data (the verdicts come from its accuracy rows)")
    problem = out_dir_problem(a.out_dir)
    if problem:
        ap.error(f"argument --out-dir: {problem}")
    if not (MODELS_DIR / a.boxnet_model).is_file():
        raise ValueError(f"--boxnet-model {a.boxnet_model}: no such shipped model in {MODELS_DIR.name}/")
    from track3d.dataset import Dataset

    # DatasetError (one line) for a folder that is no dataset or a split it does not have
    for data, splits in ((a.data if not a.no_speed else None, [a.split]), (a.accuracy_data, a.accuracy_split)):
        if data is not None:
            ds = Dataset(data)
            for split in splits:
                ds.sequences(split)
    loaded = None
    if a.data is not None and not a.no_speed:
        loaded = preload_loop_frames(a.data, a.split, a.preload, a.sequences)
    pin_threads(1)  # one thread, one core (as bench_fps --threads 1)
    res = start_record("track3d precision x engine", openvino=openvino_version(), threads=1)
    res["networks"] = {} if a.no_speed else bench_networks(a.net_seconds, a.boxnet_model)
    if loaded is not None:
        res["loop"] = bench_loop(a.data, a.split, a.frames, a.rounds, a.preload, a.sequences, a.tracker,
                                 a.boxnet_model, preloaded=loaded)
        res["data_split"] = a.split
    if a.accuracy_data is not None:
        a.out_dir.mkdir(parents=True, exist_ok=True)
        res["accuracy"] = [bench_accuracy(a.accuracy_data, split, a.out_dir, a.tracker, a.accuracy_variants,
                                          a.boxnet_model) for split in a.accuracy_split]
        if a.write_verdicts:
            print(f"wrote {write_verdicts(res['accuracy'])}")
    from track3d.boxnet import A3BoxNetEstimator
    from track3d.trackers2d import create_tracker

    trk = create_tracker(a.tracker, precision="auto", engine="auto")
    from track3d.onnxmodel import models_of

    res["auto"] = [m.describe() for m in models_of(trk).values()] + \
        [A3BoxNetEstimator(a.boxnet_model, precision="auto", engine="auto").model.describe()]
    pin_threads(len(START_CPUS))
    tag = a.tag or platform.node()
    path = write_json(a.out_dir / f"precision_{tag}.json", finish_record(res))
    md = markdown(res)
    path.with_suffix(".md").write_text(md)
    print(md)
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_precision.py"))
