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
--int8: also the configurations whose SiamFC runs its int8 graphs, the files beside its fp32
ones named as the runtime finds them (track3d.onnxmodel.variant_path: <file>_int8.onnx, e.g.
siamfc_edge_exemplar_int8.onnx; none ship, `track3d-train quantize` makes them), labelled e.g.
siamfc-edge-int8.
--precision auto: each network in the engine / precision track3d.variant_choice picks. A row's
backend and precision are what its networks RAN in ("mixed: ..." per network when they differ),
"asked" what was asked for; the record names OpenVINO's version when OpenVINO ran.

Every argument is checked before any frame is loaded or timed (one line, exit 2).

Writes <out-dir>/fps_<tag>.json (machine, CPU model, versions, every configuration) and
fps_<tag>.md (the summary table, also printed).
"""
from __future__ import annotations

import gc
import platform
import sys
from pathlib import Path

from benchlib.loop_timing import STAGES, build, load_frames, require_trackable, time_loop
from benchlib.output import add_out_argument, out_dir_problem
from benchlib.record import finish_record, start_record
from benchlib.torch_models import EquivalenceError, TorchNets

from track3d import machine
from track3d.argparsing import ArgumentParser, bounded, run_main, thread_count
from track3d.estimators import EstimatorUnavailable, available_estimators
from track3d.jsonable import write_json
from track3d.machine import pin_threads
from track3d.onnxmodel import MODELS_DIR, ModelError, model_pair, model_path, openvino_version, variant_path
from track3d.stereo import StereoCloud, StereoParams
from track3d.table_text import cell
from track3d.trackers2d import TrackerUnavailable, available_trackers

SIAMFC_STEMS = {"siamfc-edge": "siamfc_edge", "siamfc": "siamfc_faithful"}  # tracker name -> shipped stem
RATIO_STAGES = ("net2d", "net3d", "end_to_end")
UNAVAILABLE = (TrackerUnavailable, EstimatorUnavailable, ModelError)  # a missing model: skipped, not failed
NETWORK_TRACKERS = ("edgetrack", "siamfc", "siamfc-edge", "nano")   # 2D trackers that run ONNX networks
NETWORK_ESTIMATORS = ("a3boxnet",)
ONNX_TRACKERS = ("edgetrack", "siamfc", "siamfc-edge")   # 2D trackers of track3d's ONNX models (precision=, engine=)
DEFAULT_CONFIGS = ("siamfc-edge:a3boxnet", "siamfc:a3boxnet", "kcf:baseline")
SIAMFC_PARTS = ("exemplar", "search")
INT8_RULE = ("looked for <file>_int8.onnx beside each fp32 file (track3d.onnxmodel.variant_path); "
             "make them with track3d-train quantize")


def parse_config(text: str) -> tuple[str, str, str]:
    """TRACKER:ESTIMATOR[@MODEL] -> (tracker, estimator, model or ""); ValueError (one line) for a
    malformed text, a name no registry has, @MODEL with an estimator that takes no A3BoxNet file,
    or a model file that is not there."""
    pair = str(text).split(":")
    if len(pair) != 2 or not all(pair):
        raise ValueError(f"takes TRACKER:ESTIMATOR[@MODEL], got {text!r}")
    tracker, (estimator, at, model) = pair[0].lower(), pair[1].partition("@")
    estimator = estimator.lower()
    if tracker not in available_trackers():
        raise ValueError(f"unknown 2D tracker {pair[0]!r} in {text!r} (available: {', '.join(available_trackers())})")
    if estimator not in available_estimators():
        raise ValueError(f"unknown 3D box estimator {estimator!r} in {text!r} "
                         f"(available: {', '.join(available_estimators())})")
    if at and estimator not in NETWORK_ESTIMATORS:
        raise ValueError(f"{text!r}: @MODEL is an A3BoxNet .onnx, for {' / '.join(NETWORK_ESTIMATORS)} only")
    if at and not model_path(model).is_file():
        raise ValueError(f"{text!r}: no A3BoxNet file {model!r} (neither a file nor a shipped model)")
    return tracker, estimator, model


def check_args(ap: ArgumentParser, args) -> None:
    """Every mistake in the arguments as the parser's one-line error (exit 2), before any frame is
    loaded or timed: a bad configuration or model path had been timed around (then "FAILED" or
    "skipped" with result files written), a file as --out-dir failed after all the timing."""
    for text in args.config or ():
        try:
            parse_config(text)
        except ValueError as e:
            ap.error(f"argument --config: {e}")
    if args.boxnet_model is not None and not model_path(args.boxnet_model).is_file():
        ap.error(f"argument --boxnet-model: no A3BoxNet file {str(args.boxnet_model)!r} "
                 "(neither a file nor a shipped model)")
    for flag, prefix in (("--siamfc-edge-model", args.siamfc_edge_model), ("--siamfc-model", args.siamfc_model)):
        if prefix is not None:
            missing = [str(f) for f in model_pair(prefix, None, None, SIAMFC_PARTS, None) if not f.is_file()]
            if missing:
                ap.error(f"argument {flag}: no {' and no '.join(missing)} (PREFIX <dir>/<name> names the pair "
                         "<name>_exemplar.onnx / <name>_search.onnx)")
    if (args.depth == "stereo" or args.precision != ["fp32"]) and (args.torch or args.int8):
        ap.error("--depth stereo and --precision auto run the ONNX configurations only (not with --torch "
                 "or --int8)")
    problem = out_dir_problem(args.out_dir)
    if problem:
        ap.error(f"argument --out-dir: {problem}")


def cpu_shortfall(threads: list[int]) -> str | None:
    """The warning when a thread count exceeds the CPUs this process may run on (`taskset`), as
    `track3d bench` notes it: those rows run on fewer CPUs than threads; None when all fit."""
    cpus = machine.START_CPUS
    over = [t for t in threads if t > len(cpus)]
    if not over:
        return None
    return (f"warning: --threads {' '.join(map(str, over))}: only {len(cpus)} CPU(s) allowed to this process "
            f"(CPU {', '.join(map(str, cpus))}): those rows run their threads on {len(cpus)} CPU(s)")


def ran_as(networks: list[dict]) -> tuple[str, str]:
    """(backend, precision) a row's networks RAN in: one engine / precision as is, several as
    "mixed: openvino (a.onnx), onnxruntime (b.onnx, c.onnx)"; no network: ("none", "-")."""
    if not networks:
        return "none", "-"

    def label(key: str) -> str:
        groups: dict[str, list[str]] = {}
        for n in networks:
            groups.setdefault(str(n.get(key)), []).append(str(n.get("file")))
        if len(groups) == 1:
            return next(iter(groups))
        return "mixed: " + ", ".join(f"{k} ({', '.join(v)})" for k, v in groups.items())

    return label("engine"), label("precision")


def run_config(camera, sequences, cfg: dict, threads: int, frames: int, torch_nets: TorchNets | None = None) -> dict:
    """Time one configuration; a torch configuration gets torch stand-ins of the networks of
    the same configuration built from the ONNX files, passed to its tracker / estimator."""
    run_cfg, stand_ins = cfg, []
    if cfg["backend"] == "torch":
        torch_nets.torch.set_num_threads(threads)
        reference = build(camera, cfg, threads)   # the ONNX models the torch modules stand in for
        opts = {"2d": dict(cfg.get("tracker_options", {})), "3d": dict(cfg.get("estimator_options", {}))}
        for role, ckpt in cfg["checkpoints"].items():
            given = torch_nets.options(reference.tracker2d if role == "2d" else reference.estimator, ckpt, role)
            opts[role].update(given)
            stand_ins += given.values()
        del reference
        run_cfg = {**cfg, "tracker_options": opts["2d"], "estimator_options": opts["3d"]}
    stereo = (StereoCloud(camera, follow_depth=cfg["stereo_follow"], max_match_px=cfg["stereo_max_match_px"],
                          max_match_cost=cfg["stereo_max_match_cost"])
              if "stereo_follow" in cfg else None)
    t3d = build(camera, run_cfg, threads)
    networks = [{k: m.get(k) for k in ("file", "engine", "precision")} for m in t3d.describe()["models"]]
    r = time_loop(t3d, sequences, frames, stereo=stereo)
    unchecked = [m.meta.get("kind") for m in stand_ins if m.check is None]
    if unchecked:
        raise EquivalenceError(f"torch model(s) {unchecked} never ran during warm-up: equivalence not checked")
    # what ran, not what was asked: precision="auto" may run some networks on OpenVINO (torch
    # stand-ins are not files: a torch row keeps its label)
    backend, precision = (cfg["backend"], cfg["precision"]) if cfg["backend"] == "torch" else ran_as(networks)
    out = {"config": cfg["label"], "tracker": cfg["tracker"], "estimator": cfg["estimator"],
           "backend": backend, "precision": precision,
           "asked": {"engine": cfg["backend"], "precision": cfg["precision"]}, "threads": threads, "fusion": True, **r,
           **({"depth": "stereo from the pair", "stereo_follow": cfg["stereo_follow"],
               "stereo_max_match_px": cfg["stereo_max_match_px"],
               "stereo_max_match_cost": cfg["stereo_max_match_cost"]} if stereo is not None else {}),
           "networks": networks,
           "models": {"tracker_options": {k: str(v) for k, v in cfg.get("tracker_options", {}).items()},
                      "estimator_options": {k: str(v) for k, v in cfg.get("estimator_options", {}).items()}}}
    if cfg["backend"] == "torch":
        out["torch_threads"] = torch_nets.torch.get_num_threads()
        out["checkpoints"] = {k: str(v) for k, v in cfg["checkpoints"].items()}
        out["equivalence"] = [m.check for m in stand_ins]
    return out


def make_configs(args, torch_nets: TorchNets | None) -> tuple[list[dict], list[dict]]:
    """(configurations to run, skipped {config, reason}) in run order: each ORT fp32
    configuration, then its torch twin, then its int8 twin."""
    prefixes = {"siamfc-edge": args.siamfc_edge_model, "siamfc": args.siamfc_model}
    configs, skipped = [], []
    for text in args.config or DEFAULT_CONFIGS:
        tracker, estimator, model = parse_config(text)
        topt, eopt = {}, {}
        if tracker in prefixes and prefixes[tracker] is not None:
            topt["model"] = str(prefixes[tracker])
        if estimator == "a3boxnet" and (model or args.boxnet_model is not None):
            eopt["model"] = model or str(args.boxnet_model)
        label = f"{tracker}:{estimator}" + (f"@{model}" if model else "")
        # a configuration without a network (OpenCV's trackers, the baseline box) runs no backend:
        # "onnxruntime fp32" had been printed for kcf:baseline
        nets = tracker in NETWORK_TRACKERS or estimator in NETWORK_ESTIMATORS
        base = {"label": label, "tracker": tracker, "estimator": estimator, "tracker_options": topt,
                "estimator_options": eopt, "backend": "onnxruntime" if nets else "none",
                "precision": "fp32" if nets else "-"}
        # side by side: fp32, and every network in the variant precision="auto" picks on this CPU
        # (backend / precision here: what is asked; each row records what ran)
        # only to the parts that run track3d's ONNX models (kcf had been given precision= and failed);
        # a configuration without any gets no auto twin: it would run the same thing
        auto = {"precision": "auto", "engine": "auto"}
        auto_topt = {**topt, **auto} if tracker in ONNX_TRACKERS else topt
        auto_eopt = {**eopt, **auto} if estimator in NETWORK_ESTIMATORS else eopt
        precisions = args.precision if (auto_topt, auto_eopt) != (topt, eopt) else ["fp32"]
        bases = [base if p == "fp32" else {**base, "label": f"{label} auto", "backend": "auto", "precision": "auto",
                                            "tracker_options": auto_topt, "estimator_options": auto_eopt}
                 for p in precisions]
        if args.depth == "stereo":
            # one row per depth-following and row-binning setting, side by side in this run
            configs += [{**b, "label": f"{b['label']} stereo follow {k:g}" + (f" rows past {px}" if px else "")
                         + (f" cost budget {c}" if c else ""),
                         "depth_sensor": "stereo", "stereo_follow": k, "stereo_max_match_px": px,
                         "stereo_max_match_cost": c}
                        for b in bases for k in args.stereo_follow for px in args.stereo_max_match
                        for c in args.stereo_max_cost]
            continue
        if args.precision != ["fp32"]:   # no torch / int8 twins beside auto (main refuses the mix)
            configs += bases
            continue
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
            # the int8 twins as the runtime finds them (the one naming rule, also track3d-train
            # quantize's): <file>_int8.onnx beside each fp32 file; SiamFCTracker(precision="int8")
            # loads exactly those
            prefix = prefixes[tracker] if prefixes[tracker] is not None else MODELS_DIR / SIAMFC_STEMS[tracker]
            files = [variant_path(f, "int8") for f in model_pair(prefix, None, None, SIAMFC_PARTS, None)]
            label = f"{tracker}-int8:{estimator}" + (f"@{model}" if model else "")
            missing = [str(f) for f in files if not f.is_file()]
            if missing:
                skipped.append({"config": label, "backend": "onnxruntime", "int8_of": base["label"],
                                "missing_int8": missing, "reason": "no int8 file: " + ", ".join(missing)})
            else:
                configs.append({**base, "label": label, "precision": "int8",
                                "tracker_options": {**topt, "precision": "int8"}})
    return configs, skipped


def add_ratios(results: list[dict]) -> None:
    """torch rows: ORT/torch FPS (= torch ms / ORT ms, medians) of the matching ORT fp32 row;
    int8 rows: fp32/int8 ms (the int8 speed-up) of the matching fp32 ORT row."""
    ort = {(r["config"], r["threads"]): r for r in results
           if r["asked"] == {"engine": "onnxruntime", "precision": "fp32"}}
    for r in results:
        torch_row = r["asked"]["engine"] == "torch"
        if torch_row:
            ref = ort.get((r["config"], r["threads"]))
            key = "ort_over_torch_fps"
        elif r["asked"]["precision"] == "int8":
            ref = ort.get((r["config"].replace("-int8:", ":", 1), r["threads"]))
            key = "int8_speedup_vs_fp32"
        else:
            continue
        if ref is None:
            r[key] = None
            continue
        ratio = {}
        for k in RATIO_STAGES:
            mine, theirs = r["stages"][k]["median_ms"], ref["stages"][k]["median_ms"]
            num, den = (mine, theirs) if torch_row else (theirs, mine)
            ratio[k] = num / den if den > 0 else None
        r[key] = ratio


def _f(v, fmt="{:.2f}") -> str:
    return cell(v, fmt)


def markdown(out: dict) -> str:
    m = out["machine"]
    lines = [f"FPS benchmark, {out['cpu']} ({m['logical_cpus']} logical CPUs), onnxruntime "
             f"{m['versions']['onnxruntime']}" + (f", OpenVINO {out['openvino']}" if out.get("openvino") else "")
             + (f", torch {out['torch']}" if out.get("torch") else "")
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
    notes = [f"- {r['config']} at {r['threads']} threads: {r['note']}" for r in out["results"] if r.get("note")]
    if out["skipped"] or out["failed"] or notes:
        lines.append("")
    lines += notes
    for r in out["skipped"]:
        at = f", {r['threads']} threads" if "threads" in r else ""
        lines.append(f"- skipped {r['config']} ({r['backend']}{at}): {r['reason']}")
    for r in out["failed"]:
        lines.append(f"- FAILED {r['config']} ({r['backend']}, {r['threads']} threads): {r['reason']}")
    return "\n".join(lines) + "\n"


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", type=Path, required=True, help="dataset root (track3d-sim output)")
    ap.add_argument("--split", default="test", help="dataset split")
    ap.add_argument("--frames", type=bounded(int, 1), default=1000,
                    help="measured frames per configuration (>= 1000 for p99; default 1000)")
    ap.add_argument("--preload", type=bounded(int, 2), default=400,
                    help="frames kept in memory (looped over; at least a first frame and one to track; default 400)")
    ap.add_argument("--sequences", type=bounded(int, 1), default=8, help="sequences preloaded")
    ap.add_argument("--threads", type=thread_count, nargs="+", default=[1, 2],
                    help="thread counts to time, one row each (a count above the CPUs this process may run on "
                         "is warned about and noted in its row; default 1 2)")
    ap.add_argument("--config", action="append", default=None, metavar="TRACKER:ESTIMATOR[@MODEL]",
                    help=f"configurations to run (default: {' '.join(DEFAULT_CONFIGS)}); "
                         "@MODEL: this configuration's A3BoxNet .onnx (e.g. two box nets side by side in one run); "
                         "names and files are checked before anything runs")
    ap.add_argument("--depth", choices=("map", "stereo"), default="map",
                    help="map: clouds from the stored depth maps; stereo: matched from the pair inside each "
                         "update, around the 2D box (track3d.stereo.StereoCloud), with the stereo loop options "
                         "and A3BoxNet model (default map)")
    ap.add_argument("--stereo-follow", type=bounded(float, 0.0), nargs="+", default=[1.5], metavar="K",
                    help="with --depth stereo: StereoParams.follow_depth values, one row each (0: the full "
                         "disparity range every frame; default 1.5)")
    ap.add_argument("--stereo-max-match", type=bounded(int, 0), nargs="+", default=[StereoParams().max_match_px],
                    metavar="PX", help="with --depth stereo: StereoParams.max_match_px values, one row each (a "
                                       "window of more pixels is matched with its rows averaged in bands; 0: every "
                                       "row; default the matcher's)")
    ap.add_argument("--stereo-max-cost", type=bounded(int, 0), nargs="+", default=[StereoParams().max_match_cost],
                    metavar="COST", help="with --depth stereo: StereoParams.max_match_cost values, one row each (each "
                                         "update's matching budget, pixels x (disparities + 48): a dearer window "
                                         "is matched with its rows averaged in bands; 0: off; default the matcher's)")
    ap.add_argument("--precision", choices=("fp32", "auto"), nargs="+", default=["fp32"],
                    help="one row per value, side by side: fp32, every network at fp32 on onnxruntime; auto, "
                         "each in the engine and precision track3d.variant_choice picks on this CPU "
                         "(precision=auto, engine=auto; the row records the picks; default fp32)")
    ap.add_argument("--tag", default=None, help="result file name tag (default: the host name)")
    add_out_argument(ap, flag="--out-dir")
    ap.add_argument("--siamfc-edge-model", type=Path, default=None, metavar="PREFIX",
                    help="<dir>/<name> of a non-shipped <name>_exemplar.onnx/_search.onnx pair for siamfc-edge")
    ap.add_argument("--siamfc-model", type=Path, default=None, metavar="PREFIX",
                    help="the same for siamfc (faithful)")
    ap.add_argument("--boxnet-model", type=Path, default=None, metavar="ONNX", help="a non-shipped A3BoxNet ONNX")
    ap.add_argument("--int8", action="store_true",
                    help="also run each SiamFC configuration with its int8 files: <file>_int8.onnx beside each fp32 "
                         "file, e.g. siamfc_edge_exemplar_int8.onnx (track3d.onnxmodel.variant_path; none ship: "
                         "make them with track3d-train quantize); configurations without them are named in one line")
    ap.add_argument("--torch", action="store_true",
                    help="also run every SiamFC / A3BoxNet configuration in torch eager")
    ap.add_argument("--torch-siamfc-edge", type=Path, default=Path("runs/siamfc_edge/ckpt.pt"), metavar="CKPT",
                    help="torch checkpoint of siamfc-edge (--torch)")
    ap.add_argument("--torch-siamfc", type=Path, default=Path("runs/siamfc_faithful/ckpt.pt"), metavar="CKPT",
                    help="torch checkpoint of siamfc (--torch)")
    ap.add_argument("--torch-boxnet", type=Path, default=Path("runs/boxnet/main/best.pt"), metavar="CKPT",
                    help="torch checkpoint of A3BoxNet (--torch)")
    return ap


def main(argv=None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    check_args(ap, args)
    torch_nets = None
    if args.torch:
        torch_nets = TorchNets({"siamfc-edge": args.torch_siamfc_edge, "siamfc": args.torch_siamfc}, args.torch_boxnet)
    configs, skipped = make_configs(args, torch_nets)
    camera, seqs = load_frames(args.data, args.split, args.preload, args.sequences, depth=args.depth)
    require_trackable(seqs, f"{args.data} split {args.split!r}, first {args.preload} frames")
    # notes and warnings once the data is known good (a mistake stays the one line on stderr)
    short = cpu_shortfall(args.threads)
    if short:
        print(short, file=sys.stderr)
    no_int8 = [s for s in skipped if "missing_int8" in s]
    for s in skipped:
        if s not in no_int8:
            print(f"skip {s['config']} ({s['backend']}): {s['reason']}", file=sys.stderr)
    if args.int8 and not any(c["tracker"] in SIAMFC_STEMS for c in configs):
        print("--int8: no configuration runs SiamFC: no int8 row", file=sys.stderr)
    elif no_int8:
        print(f"--int8: no int8 file for {', '.join(s['int8_of'] for s in no_int8)} (no int8 row; "
              f"{INT8_RULE}): {', '.join(f for s in no_int8 for f in s['missing_int8'])}", file=sys.stderr)
    print(f"preloaded {sum(len(f) for _, f in seqs)} frames of {len(seqs)} sequences", file=sys.stderr)
    rec = start_record("track3d end-to-end FPS", data=str(args.data), split=args.split, frames_requested=args.frames)
    results, failed = [], []
    for threads in args.threads:
        pin_threads(threads)
        for cfg in configs:
            try:
                r = run_config(camera, seqs, cfg, threads, args.frames, torch_nets=torch_nets)
            except Exception as e:  # a missing model or a failed check must not lose the other configurations
                kind = "skip" if isinstance(e, UNAVAILABLE) else "FAILED"
                print(f"{kind} {cfg['label']} ({cfg['backend']}) @ {threads} threads: {type(e).__name__}: {e}",
                      file=sys.stderr)
                (failed if kind == "FAILED" else skipped).append(
                    {"config": cfg["label"], "backend": cfg["backend"], "threads": threads,
                     "reason": f"{type(e).__name__}: {e}"})
                continue
            finally:
                gc.collect()  # free the configuration's sessions before the next one loads its own
            if threads > len(machine.START_CPUS):
                r["note"] = f"only {len(machine.START_CPUS)} CPU(s) allowed"   # as track3d bench notes it
            results.append(r)
            s = r["stages"]
            print(f"{cfg['label']:24s} {r['backend']:11s} {r['precision']} threads={threads} "
                  f"fps(median)={r['fps_median']:7.1f} e2e median={s['end_to_end']['median_ms']:.2f} "
                  f"p99={s['end_to_end']['p99_ms']:.2f} ms | "
                  + " ".join(f"{k}={s[k]['median_ms']:.2f}" for k in STAGES[:-1]), flush=True)
    pin_threads(max(args.threads))
    add_ratios(results)
    ran_openvino = any(n.get("engine") == "openvino" for r in results for n in r["networks"])
    out = finish_record({**rec, "torch": torch_nets.torch.__version__ if torch_nets else None,
                         "openvino": openvino_version() if ran_openvino else None,
                         "note": "I/O excluded; threads=1 runs pinned to one core (every thread); "
                                 "ort_over_torch_fps = torch median ms / onnxruntime median ms of the same "
                                 "configuration (> 1: onnxruntime faster); int8_speedup_vs_fp32 = fp32 median ms / "
                                 "int8 median ms",
                         "results": results, "skipped": skipped, "failed": failed})
    tag = args.tag or platform.node()
    path = write_json(args.out_dir / f"fps_{tag}.json", out)
    md = markdown(out)
    (args.out_dir / f"fps_{tag}.md").write_text(md)
    print(md)
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_fps.py"))
