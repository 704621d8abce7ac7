"""The `track3d` command: track, eval, bench, trackers.

    track3d track --data data/small --split test --tracker kcf --estimator baseline
    track3d eval  --data data/small --split test --results results --out reports
    track3d-sim demo --out track3d-demo   # simulate, track, evaluate (the sim extra)
    track3d trackers                       # the registered 2D trackers and box estimators
    track3d bench                          # FPS of the shipped models on this CPU (no dataset needed)
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from .argparsing import ArgumentParser, apply_formatter, bounded, hidden_alias, package_version, thread_count

__all__ = ["main"]

from .evaluation.tables import (axis_table, condition_table, paired_table, sequence_table,  # noqa: E402  (the tables of a report)
                                summary_table)
from .threads import set_threads  # noqa: E402

def _stereo_params(opts: dict, depth: str):
    """--stereo-option's KEY=VALUE pairs (parsed) as a track3d.stereo.StereoParams, None if none;
    ValueError (one line) for a key that is not a setting, a bad value, or no --depth stereo."""
    if not opts:
        return None
    from dataclasses import fields

    from .stereo import StereoParams

    if depth != "stereo":
        raise ValueError("--stereo-option sets the matcher of --depth stereo: add --depth stereo")
    known = {f.name for f in fields(StereoParams)}
    unknown = sorted(set(opts) - known)
    if unknown:
        raise ValueError(f"unknown --stereo-option {', '.join(unknown)}: one of {', '.join(sorted(known))}")
    try:
        return StereoParams(**opts)
    except TypeError as e:   # a value of the wrong kind that the dataclass passed on
        raise ValueError(f"bad --stereo-option: {e}") from None


_INT = re.compile(r"[+-]?\d+")
_FLOAT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _options(pairs: list[str] | None) -> dict:
    """key=value pairs -> dict, values parsed as int / float / bool when they are written as one.
    Only plain decimal numbers are numbers: "nan", "inf" or "1_000" reached a plug-in's factory
    as floats (Python's float() takes them) where it meant a name (a plug-in walkthrough)."""
    out = {}
    for p in pairs or []:
        if "=" not in p:
            raise ValueError(f"option {p!r} is not key=value")
        k, v = p.split("=", 1)
        if _INT.fullmatch(v):
            out[k] = int(v)
        elif _FLOAT.fullmatch(v):
            out[k] = float(v)
        else:
            out[k] = {"true": True, "false": False}.get(v.lower(), v)
    return out


def _front_filter(text: str) -> tuple[float, float] | bool:
    """argparse type of --front-filter: "ALPHA,BETA" -> (alpha, beta); "off" -> False (none)."""
    if text.strip().lower() == "off":
        return False
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected ALPHA,BETA (e.g. 0.8,0.2) or off, got {text!r}") from None
    if not (0.0 < a <= 1.0 and 0.0 <= b <= 1.0):
        raise argparse.ArgumentTypeError(f"expected 0 < ALPHA <= 1 and 0 <= BETA <= 1, got {text!r}")
    return a, b


def _section_limbs(text: str) -> tuple[float, float, float] | bool:
    """argparse type of --section-limbs: "PX,SHARE,Q" -> (px, share, q); "off" -> False (none)."""
    if text.strip().lower() == "off":
        return False
    try:
        px, share, q = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected PX,SHARE,Q (e.g. 4,0.05,0.9) or off, got {text!r}") from None
    if not (0.0 <= px <= 100.0 and 0.0 <= share < 0.5 and max(px, share) > 0.0 and 0.0 <= q <= 1.0):
        raise argparse.ArgumentTypeError(f"expected 0 <= PX <= 100, 0 <= SHARE < 0.5 (not both 0) and 0 <= Q <= 1, "
                                         f"got {text!r}")
    return px, share, q


def _result_name(text: str) -> str:
    """argparse type: a result name is one folder under <results>/<split>/; "a/b" or "../x"
    would write beside or outside the results, where `track3d eval` never looks."""
    if not text or text in (".", "..") or "/" in text or "\\" in text:
        raise argparse.ArgumentTypeError(f"a result name is one folder name (no '/', '\\', '.' or '..'), got {text!r}")
    return text


def _unique(names: list[str] | None) -> list[str] | None:
    """Names in their order, each once (`--sequence a a` is one sequence, not two runs of it)."""
    return None if names is None else list(dict.fromkeys(names))


def _add_data_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="dataset root (the folder with dataset.json)")
    p.add_argument("--split", default="test", help="dataset split (default: test)")
    p.add_argument("--sequence", "--sequences", dest="sequences", nargs="+", metavar="NAME",
                   help="only these sequences of the split")
    p.add_argument("--frames", type=bounded(int, 1), help="only the first N (>= 1) frames of each sequence (default: all)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    hidden_alias(p, "--no-progress", "quiet", action="store_true")


def _add_plugin_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plugin", action="append", dest="plugins", metavar="MODULE", default=[],
                   help="import this module (dotted name or .py file) first: it registers its trackers "
                        "or estimators (repeatable; entry points of the groups track3d.trackers / "
                        "track3d.estimators load by themselves)")


def _parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog="track3d", description="Track3D: 3D asteroid tracking runtime "
                                 "(2D tracker -> frustum -> 3D box estimator -> 2D-3D fusion).")
    ap.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    ap.add_argument("--plugin", action="append", dest="plugins_top", metavar="MODULE", default=[],
                    help="import this module (dotted name or .py file) first: it registers its trackers or "
                         "estimators (repeatable; also accepted after the command)")
    sub = ap.add_subparsers(dest="command", required=True)

    t = sub.add_parser("track", help="run a 2D tracker x box estimator on a split or sequences; "
                                     "writes GOT-10k style results and an overlay video")
    _add_data_args(t)
    t.add_argument("--tracker", default="edgetrack",
                   help="2D tracker name (see `track3d trackers`; default edgetrack, Track3D's default)")
    t.add_argument("--estimator", default="a3boxnet",
                   help="3D box estimator name (see `track3d trackers`; default a3boxnet)")
    t.add_argument("--tracker-option", action="append", metavar="KEY=VALUE",
                   help="an option of the 2D tracker, repeatable (e.g. model=<dir>/<name>, threads=2; a key the "
                        "tracker does not take is answered with the keys it takes)")
    t.add_argument("--estimator-option", action="append", metavar="KEY=VALUE",
                   help="an option of the 3D box estimator, repeatable (e.g. model=a3boxnet_narrow.onnx, views=4; "
                        "a key the estimator does not take is answered with the keys it takes)")
    t.add_argument("--no-fusion", action="store_true", help="report the 2D tracker's box, no 2D-3D fusion")
    t.add_argument("--weight-3d", type=bounded(float, 0, high=1), default=None,
                   help="fusion weight of the projected 3D box (default: by the depth sensor: 0 for ideal and "
                        "flash-LiDAR depth, whose outline sets the 2D box, 0.15 for ToF and stereo, the paper's 0.3 "
                        "for an unknown sensor; track3d.sensor_options.fusion_weight_for)")
    t.add_argument("--weight-2d", type=bounded(float, 0, high=1), default=None,
                   help="weight of the 2D box in the 3D box's cross-section (the reverse fusion; default: by the "
                        "depth sensor, 0, 0.75 for stereo; track3d.sensor_options.section_weight_for)")
    t.add_argument("--section-limbs", type=_section_limbs, default=None, metavar="PX,SHARE,Q|off",
                   help="in that cross-section, put each side of the 2D box at its limb's depth: the Q quantile of "
                        "the depth of the returns within max(PX pixels, SHARE of the box) of the side (off: every "
                        "side at the box's centre depth; default by the depth sensor, track3d.sensor_options."
                        "section_limbs_for: stereo 4,0.05,0.9, others off)")
    t.add_argument("--no-measured-faces", action="store_true",
                   help="report the estimator's box as it is (default: the faces the depth sensor sees, x / y extent "
                        "and front, from the returns, except for stereo depth; track3d.sensor_options.measured_faces_for)")
    t.add_argument("--depth-smoothing", type=bounded(float, 0, high=0.99), default=None,
                   help="weight of the running average in the box's depth extent, front face kept (0: each "
                        "frame's estimate; default track3d.tracker.DEPTH_SMOOTHING, 0.5)")
    t.add_argument("--evidence-points", type=bounded(int, 0), default=None,
                   help="a frame the 2D tracker calls lost is held ('no_points'), not 'lost', when at least this "
                        "many depth returns remain in the frustum of the last box (a body at the image border; "
                        "0: off; default track3d.tracker.EVIDENCE_POINTS, 48; trackers that judge their loss)")
    t.add_argument("--reacquire-threshold", type=bounded(float, 0, high=1), default=None,
                   help="the score a lost 2D tracker that judges its loss needs to take a candidate inside the "
                        "loop (raised to this, never lowered; 0: the tracker's own; default "
                        "track3d.tracker.REACQUIRE_THRESHOLD, 0.9)")
    t.add_argument("--hold-cut-size", type=bounded(float, 0, high=1), default=None,
                   help="a body cut by the image border keeps, on the cut axis, its extent from the last whole view "
                        "when the returns span less than this fraction of it (0: off; default "
                        "track3d.tracker.HOLD_CUT_SIZE, 0.8; the returns' extent with measured faces, the 2D "
                        "box's cross-section without: stereo)")
    t.add_argument("--edge-pad", type=bounded(float, 0, high=10), default=None, metavar="PX",
                   help="pixels added to the returns' extent across the line of sight (half on each side: the "
                        "outline lies beyond the outermost pixel centres; 0: off; default "
                        "by the depth sensor, track3d.sensor_options.edge_pad_for: 1, ToF 3; with measured faces)")
    t.add_argument("--front-quantile", type=bounded(float, 0, high=0.1), default=None, metavar="Q",
                   help="the quantile of the returns' depth taken as the body's front face (0: the nearest return; "
                        "a noisy sensor's nearest return lies in front of the surface; default by the depth "
                        "sensor, track3d.sensor_options.front_quantile_for: 0, ToF 0.005)")
    t.add_argument("--silhouette", type=bounded(float, 0, high=4), default=None, metavar="GROW",
                   help="start from the body's outline in the depth returns: the connected returns overlapping the "
                        "2D box, searched in the box grown by GROW of its size on each side (0: off; default by the "
                        "depth sensor, track3d.sensor_options.silhouette_for: 0.5, stereo 0)")
    t.add_argument("--outline-share", type=bounded(float, 0, high=1), default=None, metavar="S",
                   help="with the outline off (--silhouette 0), its share in the box the 2D fusion starts from and "
                        "the 2D tracker is corrected with (0: none; default by the depth sensor, "
                        "track3d.sensor_options.outline_share_for: stereo 0.3, others 0)")
    t.add_argument("--outline-share-phase", type=bounded(float, 0, high=180), default=None, metavar="DEG",
                   help="with the sun's direction known (meta.json sun), the largest phase angle at the 2D box "
                        "(sun - body - camera, degrees) at which the outline keeps its --outline-share: past it the "
                        "lit part is a crescent, not the body's size (180: always; default by the depth sensor, "
                        "track3d.sensor_options.outline_share_phase_for: stereo 90, others 180)")
    t.add_argument("--outline-contain", action=argparse.BooleanOptionalAction, default=None,
                   help="with the outline off (--silhouette 0), move the 2D tracker's box (its size kept) to hold "
                        "the outline before the frustum and the fusion, and with no returns near it go to the body "
                        "the whole view's depth shows (default by the depth sensor, "
                        "track3d.sensor_options.outline_contain_for: on for stereo, off for the others)")
    t.add_argument("--texture-trim", action=argparse.BooleanOptionalAction, default=None,
                   help="with the box moved to hold the outline (--outline-contain), pull its sides in off image "
                        "texture the depth did not match (stereo: a moon or a star field behind the body; default by "
                        "the depth sensor, track3d.sensor_options.texture_trim_for: on for stereo, off for the others)")
    t.add_argument("--drop-stray", action=argparse.BooleanOptionalAction, default=None,
                   help="leave a depth sensor's false alarms out of every frustum: lone returns in the image, a "
                        "few returns apart in depth (track3d.stray_returns; default by the depth sensor, "
                        "track3d.sensor_options.drop_stray_for: on for every sensor)")
    t.add_argument("--resume-outline", action=argparse.BooleanOptionalAction, default=None,
                   help="when a 2D tracker that judges its loss (EdgeTrack) calls a frame lost while the depth's "
                        "outline at its last box holds the body in view, go on from the outline (stereo: from the "
                        "last box moved onto the lit outline; default by the depth sensor, "
                        "track3d.sensor_options.resume_outline_for: on for every sensor named, off for an unknown one)")
    t.add_argument("--front-filter", type=_front_filter, default=None, metavar="ALPHA,BETA|off",
                   help="follow the 3D box's front face over frames with an alpha-beta filter, e.g. 0.8,0.2 "
                        "(0 < ALPHA <= 1, 0 <= BETA <= 1; off: none; default by the depth sensor, "
                        "track3d.sensor_options.front_filter_for: stereo 0.8,0.2, others off)")
    t.add_argument("--dark-side", type=bounded(float, 0, high=2), default=None, metavar="K",
                   help="with the outline off (--silhouette 0) and the sun's direction known (meta.json sun), the 2D "
                        "box reaches past the lit outline on the side away from the sun by K x a sphere's dark part "
                        "(0: off, the default for every sensor, track3d.sensor_options.dark_side_for; 0.1 was measured for stereo, docs/runtime.md)")
    t.add_argument("--fusion-cover", type=bounded(float, 0, high=1), default=None, metavar="SHARE",
                   help="when fewer than SHARE of the 2D box's pixels hold a return (stereo: a body mostly in "
                        "shadow), neither the depth's outline nor the 3D box moves the 2D box (0: off; default by "
                        "the depth sensor, track3d.sensor_options.fusion_cover_for: 0 for every sensor)")
    t.add_argument("--no-sun", action="store_true",
                   help="ignore the sun's direction recorded with each sequence (meta.json sun.direction)")
    t.add_argument("--body-views", action=argparse.BooleanOptionalAction, default=None,
                   help="keep the body's past views in a body-fixed frame (registered from the depth alone) and "
                        "hold the 3D box's back face at least at the farthest point they saw (default by the depth "
                        "sensor, track3d.sensor_options.body_views_for: on, off for stereo)")
    t.add_argument("--body-views-option", action="append", metavar="KEY=VALUE",
                   help="a setting of the body's past views (track3d.body_views.BodyViewsParams, e.g. every=5, "
                        "carve_views=0: no carving, cut_extent=0: a cut body keeps its last whole view's extent); "
                        "turns the views on; the results are named <tracker>+<estimator>-views-KEY=VALUE unless "
                        "--name is given")
    t.add_argument("--frustum-margin", type=bounded(float, 0, high=1), default=None,
                   help="the frustum is cut with the 2D box widened by this fraction of its size (0: the box "
                        "itself; default: by the depth sensor, 0.3, 0 for stereo; track3d.sensor_options.frustum_margin_for)")
    t.add_argument("--no-depth-range", action="store_true",
                   help="ignore the depth sensor's maximum range recorded with each sequence (meta.json "
                        "depth_sensor.max_range_m); by default a body whose returns stop at that range is boxed from "
                        "the image and its front face (track3d.range_cut)")
    t.add_argument("--threads", type=thread_count, default=1, help="CPU threads of the ONNX models (default 1)")
    t.add_argument("--precision", choices=("fp32", "int8", "bf16", "auto"), default=None,
                   help="arithmetic of the networks (EdgeTrack, SiamFC, A3BoxNet); int8: every network the run "
                        "uses needs its int8 file beside it (shipped: a3boxnet_int8.onnx only, for "
                        "--estimator-option model=a3boxnet.onnx; make others with `track3d-train quantize`); "
                        "bf16: with --engine openvino; auto: the fastest this CPU allows, measured once and "
                        "cached (default fp32)")
    t.add_argument("--engine", choices=("onnxruntime", "openvino", "auto"), default=None,
                   help="inference engine of the networks; openvino needs track3d[openvino] (default onnxruntime)")
    t.add_argument("--results", default="results", help="result folder (default ./results)")
    t.add_argument("--name", type=_result_name, help="result name (default <tracker>+<estimator>, tagged @<model>-<hash> when a "
                                  "model option names the model file)")
    t.add_argument("--replace", action="store_true",
                   help="replace results of another configuration or over other frames (--frames) under the same name "
                        "(default: refuse)")
    t.add_argument("--restart-skip", type=bounded(int, 1), default=1,
                   help="re-initialise this many frames after a zero-3D-IoU frame (default 1: the next)")
    t.add_argument("--no-restart", action="store_true", help="never re-initialise from the ground truth")
    t.add_argument("--init-3d", action="store_true",
                   help="3D single-object tracking's start (KITTI's protocol): every initialisation also gets the "
                        "ground truth's 3D box of that frame, whose depth extent holds while the body has not turned "
                        "(track3d.first_box); another protocol: the results are named <tracker>+<estimator>-init3d "
                        "unless --name is given")
    t.add_argument("--first-box-fade", type=bounded(float, above=0, high=10), default=None, metavar="CHANGE",
                   help="with --init-3d, the relative change of the lateral extents at which the first box's depth "
                        "no longer counts (default by the depth sensor, track3d.sensor_options.first_box_fade_for: 0.5 for "
                        "stereo and ToF, 0.2 for the others)")
    t.add_argument("--depth", choices=("map", "stereo"), default="map",
                   help="point clouds from the dataset's depth maps (map, default) or computed from its "
                        "left/right images by semi-global matching around the 2D box (stereo)")
    t.add_argument("--stereo-option", action="append", metavar="KEY=VALUE",
                   help="with --depth stereo, a setting of the matcher (track3d.stereo.StereoParams, e.g. "
                        "follow_depth=0: the full disparity range every frame, z_min_m=3, mode=sgbm); the results "
                        "are named <tracker>+<estimator>-stereo-KEY=VALUE unless --name is given")
    t.add_argument("--video", choices=("auto", "gif", "mp4", "none"), default="auto",
                   help="overlay format (default auto: gif when pillow is installed, else mp4; gif needs pillow)")
    t.add_argument("--video-sequences", type=bounded(int, 0), default=1, help="how many sequences get an overlay")

    e = sub.add_parser("eval", help="results vs ground truth -> report.json, table and plots")
    _add_data_args(e)
    e.add_argument("--results", default="results", help="result folder of `track3d track` (default ./results)")
    e.add_argument("--trackers", nargs="+", help="result names to compare (default: all in the folder)")
    e.add_argument("--out", default="reports", help="report folder (default ./reports)")
    e.add_argument("--baseline", metavar="NAME",
                   help="the run the others are compared with sequence by sequence (mean difference, its "
                        "bootstrap interval, sequences better / worse; default: the first compared run)")
    e.add_argument("--no-plots", action="store_true", help="skip the plots (no matplotlib needed)")
    e.add_argument("--tracker-boxes", action="store_true",
                   help="score the 2D trackers' own boxes (_raw_001.txt, before the loop corrected them), in 2D "
                        "only: with ideal or flash-LiDAR depth the reported boxes follow the depth's outline "
                        "whatever the tracker did, so they say little of the 2D tracker itself")
    e.add_argument("--trajectories", type=bounded(int, 0), default=4,
                   help="sequences with a 3D trajectory plot and a line-of-sight plot (depth_<seq>.png): the "
                        "worst ones, lowest AO_3d averaged over the compared runs (default 4)")
    e.add_argument("--trajectories-of", choices=("worst", "first"), default="worst",
                   help="which sequences get trajectory and line-of-sight plots: the worst (default) or the "
                        "split's first")
    e.add_argument("--per-sequence", action="store_true",
                   help="also print each sequence's scores, the runs side by side (AO, ACE_3d, the line-of-sight "
                        "biases and the change against --baseline); always written to sequences.txt in --out")

    # The demo simulates its data, so it lives with the simulator (`track3d-sim demo`): the
    # runtime never imports the simulator. This entry only says where it went.
    sub.add_parser("demo", help="moved: run `track3d-sim demo` (needs pip install 'track3d[sim]')")

    dc = sub.add_parser("docs", help="the documents help texts name (docs/runtime.md, ...), shipped with the "
                                     "package: list them, or print one")
    dc.add_argument("name", nargs="?", help="the document to print: runtime, models, results, simulator, "
                                            "dataset or readme (default: list them with their paths)")

    tr = sub.add_parser("trackers", help="list the registered 2D trackers and 3D box estimators (plug-ins included)")
    _add_plugin_arg(tr)
    _add_plugin_arg(t)
    _add_plugin_arg(e)

    b = sub.add_parser("bench", help="time the loop (or each network) on this CPU: per-stage median, p99, "
                                     "p99.9, max ms and FPS at 1 and 2 threads, pinned; no dataset needed",
                       formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    b.add_argument("--tracker", default="edgetrack", help="2D tracker name")
    b.add_argument("--estimator", default="a3boxnet", help="3D box estimator name")
    b.add_argument("--tracker-model", metavar="PREFIX",
                   help="<dir>/<name> prefix of the tracker's ONNX pair (EdgeTrack: <name>_template.onnx / _search.onnx; SiamFC: _exemplar / _search) (default: shipped)")
    b.add_argument("--boxnet-model", metavar="ONNX", help="an A3BoxNet ONNX file (default: shipped)")
    b.add_argument("--frames", type=bounded(int, 1), default=1000, help="timed frames per thread count (after 20 warm-up)")
    b.add_argument("--threads", type=thread_count, nargs="+", default=[1, 2], help="thread counts to time (default: 1 2)")
    b.add_argument("--data", help="time on this dataset's first sequences instead of synthetic frames")
    b.add_argument("--split", default="test", help="dataset split with --data")
    b.add_argument("--sequence", "--sequences", dest="sequences", nargs="+", metavar="NAME",
                   help="with --data: only these sequences (default: the split's first)")
    b.add_argument("--models-only", action="store_true",
                   help="time each network alone on the inputs it gets in the loop (onnxruntime_perf_test style)")
    b.add_argument("--depth", choices=("map", "stereo"), default="map",
                   help="map: the clouds are given (a depth sensor); stereo: a stereo camera's loop, the cloud "
                        "matched from the left/right pair around the 2D box inside each update, with the stereo "
                        "loop options and A3BoxNet model; the matching's time and its price on this CPU (ns per "
                        "unit of cost, the max_match_cost for 5 / 10 / 20 ms) are reported")
    b.add_argument("--stereo-option", action="append", metavar="KEY=VALUE",
                   help="with --depth stereo, a setting of the matcher (track3d.stereo.StereoParams, e.g. "
                        "max_match_px=16384: a large window's rows averaged in bands, faster; max_match_cost=12000000: "
                        "a matching budget per update, only the dearest windows binned: a bounded frame time)")
    b.add_argument("--precision", choices=("fp32", "int8", "bf16", "auto"), default=None,
                   help="arithmetic of the networks, as `track3d track --precision` (default: fp32); auto: "
                        "the fastest this CPU allows, measured; the report's `track3d` record says what ran and why")
    b.add_argument("--engine", choices=("onnxruntime", "openvino", "auto"), default=None,
                   help="inference engine of the networks, as `track3d track --engine` (default: onnxruntime)")
    b.add_argument("--out", metavar="JSON", help="also write the report as JSON here")
    b.add_argument("--json", action="store_true", help="print the JSON report instead of the table")
    b.add_argument("--quiet", action="store_true", help="no progress messages on stderr")
    hidden_alias(b, "--no-progress", "quiet", action="store_true")
    _add_plugin_arg(b)
    return apply_formatter(ap)


def _cmd_bench(a) -> int:
    import json

    from .bench import BenchConfig, format_table, run_bench
    from .jsonable import jsonable, write_json

    cfg = BenchConfig(tracker=a.tracker, estimator=a.estimator, tracker_model=a.tracker_model,
                      boxnet_model=a.boxnet_model, frames=a.frames, threads=tuple(a.threads), data=a.data,
                      split=a.split, sequences=tuple(a.sequences) if a.sequences else None,
                      models_only=a.models_only, depth=a.depth,
                      stereo=_stereo_params(_options(a.stereo_option), a.depth),
                      precision=a.precision, engine=a.engine)
    if a.split != "test" and not a.data:
        raise ValueError(f"--split {a.split} needs --data (without it the frames are synthetic)")
    if a.tracker_model and not Path(a.tracker_model).parent.is_dir():
        raise FileNotFoundError(f"--tracker-model {a.tracker_model}: no folder {Path(a.tracker_model).parent}")
    if a.boxnet_model and not Path(a.boxnet_model).is_file():
        raise FileNotFoundError(f"--boxnet-model {a.boxnet_model}: no such file")
    from .estimators import available_estimators, create_estimator
    from .trackers2d import available_trackers, create_tracker

    # an unknown name before the frames are made (the registries' own messages)
    if str(a.tracker).lower() not in available_trackers():
        create_tracker(a.tracker)
    if str(a.estimator).lower() not in available_estimators():
        create_estimator(a.estimator)
    if a.out and Path(a.out).is_dir():  # before the timing, not after minutes of it
        raise ValueError(f"--out {a.out} is a folder: give the JSON file to write")
    report = run_bench(cfg, log=None if a.quiet else (lambda s: print(f"[bench] {s}", file=sys.stderr)))
    print(json.dumps(jsonable(report), indent=1) if a.json else format_table(report))
    if a.out:
        print(f"report: {write_json(a.out, report)}", file=sys.stderr)
    return 0


def _cmd_track(a) -> int:
    from .evaluation import Experiment, TrackerSpec

    set_threads(a.threads)
    video = _video_format(a.video)
    topts, eopts = _options(a.tracker_option), _options(a.estimator_option)
    arith = {k: v for k, v in (("precision", a.precision), ("engine", a.engine)) if v is not None}
    if a.tracker.startswith("siamfc") or a.tracker == "edgetrack":  # the networks; the others have no variants
        topts = {**arith, **topts}
    if a.estimator == "a3boxnet":
        eopts = {**arith, **eopts}
    from .sensor_options import sensor_options

    # stereo computed here from the image pairs: the stereo sensor's options; else the dataset's
    # sensor decides per sequence (None)
    stereo = sensor_options("stereo") if a.depth == "stereo" else {}
    margin = a.frustum_margin if a.frustum_margin is not None else stereo.get("frustum_margin")
    weight = a.weight_3d if a.weight_3d is not None else stereo.get("weight_3d")
    weight_2d = a.weight_2d if a.weight_2d is not None else stereo.get("weight_2d")
    faces = False if a.no_measured_faces else stereo.get("measured_faces")
    limbs = a.section_limbs if a.section_limbs is not None else stereo.get("section_limbs")
    if a.depth == "stereo" and a.silhouette is None:
        a.silhouette = stereo.get("silhouette")
    if a.depth == "stereo" and a.outline_share is None:
        a.outline_share = stereo.get("outline_share")
    if a.depth == "stereo" and a.outline_share_phase is None:
        a.outline_share_phase = stereo.get("outline_share_phase")
    if a.depth == "stereo" and a.outline_contain is None:
        a.outline_contain = stereo.get("outline_contain")
    if a.depth == "stereo" and a.texture_trim is None:
        a.texture_trim = stereo.get("texture_trim")
    if a.depth == "stereo" and a.fusion_cover is None:
        a.fusion_cover = stereo.get("fusion_cover")
    if a.depth == "stereo" and a.body_views is None:
        a.body_views = stereo.get("body_views")
    views_opts = _options(a.body_views_option)
    if views_opts:
        from dataclasses import fields

        from .body_views import BodyViewsParams

        if a.body_views is False:
            raise ValueError("--body-views-option needs the body's views: drop --no-body-views")
        known = {f.name for f in fields(BodyViewsParams)}
        unknown = sorted(set(views_opts) - known)
        if unknown:
            raise ValueError(f"unknown --body-views-option {', '.join(unknown)}: one of {', '.join(sorted(known))}")
        a.body_views = BodyViewsParams(**views_opts)
    if a.depth == "stereo" and a.estimator == "a3boxnet" and "model" not in eopts:
        eopts.setdefault("depth_sensor", "stereo")   # the stereo model (track3d.boxnet.SENSOR_MODELS)
    spec = TrackerSpec(a.tracker, a.estimator, fusion=not a.no_fusion, weight_3d=weight, threads=a.threads,
                       weight_2d=weight_2d, section_limbs=limbs, measured_faces=faces, depth_smoothing=a.depth_smoothing,
                       evidence_points=a.evidence_points, reacquire_threshold=a.reacquire_threshold,
                       hold_cut_size=a.hold_cut_size, edge_pad=a.edge_pad,
                       first_box_fade=a.first_box_fade if a.first_box_fade is not None else stereo.get("first_box_fade"),
                       front_quantile=a.front_quantile, front_filter=a.front_filter, silhouette=a.silhouette,
                       outline_share=a.outline_share, outline_share_phase=a.outline_share_phase,
                       outline_contain=a.outline_contain, texture_trim=a.texture_trim, resume_outline=a.resume_outline,
                       drop_stray=a.drop_stray, dark_side=a.dark_side, fusion_cover=a.fusion_cover, sun=not a.no_sun,
                       body_views=a.body_views,
                       frustum_margin=margin,
                       # clouds from the image pairs have the stereo camera's reach, not the recorded sensor's
                       depth_range=not a.no_depth_range and a.depth != "stereo",
                       tracker_options=topts, estimator_options=eopts, name=a.name)
    if views_opts and not a.name:   # keep the default views' results of the same pair
        spec.name = spec.label + "-views-" + "-".join(f"{k}={v}" for k, v in sorted(views_opts.items()))
    stereo_opts = _options(a.stereo_option)
    stereo_params = _stereo_params(stereo_opts, a.depth)
    if a.depth == "stereo" and not a.name:
        spec.name = spec.label + "-stereo"   # keep the depth-map results of the same pair
        if stereo_opts:
            spec.name += "-" + "-".join(f"{k}={v}" for k, v in sorted(stereo_opts.items()))
    if a.first_box_fade is not None and not a.init_3d:
        raise ValueError("--first-box-fade weighs the first 3D box: it needs --init-3d")
    if a.init_3d and not a.name:
        spec.name = spec.label + "-init3d"   # another protocol: never the same folder as the 2D start's
    exp = Experiment(a.data, a.split, a.results, sequences=_unique(a.sequences), max_frames=a.frames,
                     restart=not a.no_restart, restart_skip=a.restart_skip, depth=a.depth, init_3d=a.init_3d,
                     stereo_params=stereo_params)
    results = Path(a.results)
    if results.exists() and not results.is_dir():
        raise ValueError(f"--results {results} is a file, not a folder")
    # Build once up front so that an unknown name or a missing model fails before any work.
    try:
        spec.build(exp.sequences[0])
    except TypeError as e:  # an option the tracker or estimator does not take
        raise ValueError(f"bad --tracker-option / --estimator-option for {a.tracker} / {a.estimator}: {e}") from None
    except ValueError as e:
        # a value the tracker or estimator refused in words that do not name it ("could not
        # convert string to float: 'abc'"): say which options were given
        # the user's own, not the options the command adds (precision, depth_sensor)
        given = [(f"--tracker-option {p}", p.split("=", 1)[0]) for p in a.tracker_option or []] + \
                [(f"--estimator-option {p}", p.split("=", 1)[0]) for p in a.estimator_option or []]
        if given and not any(k in str(e) for _, k in given):
            raise ValueError(f"{e} (given: {', '.join(g for g, _ in given)})") from None
        raise
    folders = exp.run(spec, overlay=video,
                      overlay_sequences=a.video_sequences, quiet=a.quiet, replace=a.replace)
    root = Path(a.results) / a.split / spec.label
    print(f"results of {spec.label} on {len(folders)} sequence(s) of {a.data}/{a.split}: {root}")
    for f in folders[:a.video_sequences]:
        for v in sorted(f.glob("*_overlay.*")):
            print(f"overlay: {v}")
    return 0


def _video_format(choice: str) -> str | None:
    """--video -> "gif" / "mp4" / None; gif needs pillow (say so instead of writing an mp4)."""
    import importlib.util

    has_pil = importlib.util.find_spec("PIL") is not None
    if choice == "none":
        return None
    if choice == "auto":
        return "gif" if has_pil else "mp4"
    if choice == "gif" and not has_pil:
        raise ValueError("--video gif needs pillow: pip install 'track3d[plot]' (or use --video mp4)")
    return choice


def _cmd_eval(a) -> int:
    from .evaluation import Experiment
    from .evaluation.results import result_folder
    from .jsonable import write_json

    split_dir = Path(a.results) / a.split
    if Path(a.out).exists() and not Path(a.out).is_dir():
        raise ValueError(f"--out {a.out} is a file, not a folder")
    results = Path(a.results)
    if results.exists() and not results.is_dir():
        raise ValueError(f"--results {results} is a file, not a folder (the folder `track3d track --results` wrote)")
    if not results.exists():
        raise FileNotFoundError(f"--results {results}: the folder does not exist (run `track3d track --results "
                                f"{results}` first)")
    # the dataset and its split first: a wrong --split is the split's fault, not the results'
    exp = Experiment(a.data, a.split, a.results, a.out, sequences=_unique(a.sequences), max_frames=a.frames,
                     own_2d=a.tracker_boxes)
    if a.trackers:
        names = _unique(a.trackers)
    elif split_dir.is_dir():
        names = sorted(p.name for p in split_dir.iterdir() if p.is_dir())
    else:
        names = []
    if not names:
        hint = ""
        if results.name == a.split:
            hint = f" (--results is the folder `track3d track --results` wrote: {results.parent})"
        elif results.parent.name == a.split:
            hint = (f" (--results is the folder `track3d track --results` wrote, {results.parent.parent}; "
                    f"--trackers {results.name} to compare that run alone)")
        raise FileNotFoundError(f"no results in {split_dir}{hint or ' (run `track3d track` first)'}")
    notes = []
    if not a.sequences:
        # Default: the sequences every named tracker has results for.
        def done(n: str, s) -> bool:
            return (result_folder(a.results, a.split, n, s.name) / f"{s.name}_status.txt").is_file()

        def why_none(n: str) -> str:
            """Why run `n` has no finished sequence, where the folders say more than that."""
            if not (split_dir / n).is_dir():
                there = sorted(p.name for p in split_dir.iterdir() if p.is_dir()) if split_dir.is_dir() else []
                return f" (no folder {split_dir / n}; runs there: {', '.join(there) or 'none'})"
            # another toolkit's layout (GOT-10k's): boxes without the status file this format needs
            boxes_only = [s.name for s in exp.sequences
                          if (result_folder(a.results, a.split, n, s.name) / f"{s.name}_001.txt").is_file()]
            if boxes_only:
                return (f" ({n}/{boxes_only[0]} has {boxes_only[0]}_001.txt but no {boxes_only[0]}_status.txt: "
                        "one word a frame, 'init' on the first, 'tracking' after it; docs/runtime.md, "
                        "'Scoring another tracker's result files')")
            return ""

        if not a.trackers:   # folders with no finished sequence (a run that failed): left out, said so
            empty = [n for n in names if not any(done(n, s) for s in exp.sequences)]
            if empty and len(empty) < len(names):
                names = [n for n in names if n not in empty]
                notes.append(f"left out {', '.join(empty)}: no finished sequence of {a.data}/{a.split}"
                             + "".join(why_none(n) for n in empty[:2]))
        have = [s for s in exp.sequences if all(done(n, s) for n in names)]
        if not have:
            why = "".join(why_none(n) for n in names if not any(done(n, s) for s in exp.sequences))
            raise FileNotFoundError(f"no sequence of {a.data}/{a.split} has results of {', '.join(names)} "
                                    f"in {a.results}{why}")
        if len(have) < len(exp.sequences):
            # name what is missing: a sequence folder without its status file (written last) is a
            # run killed on it, or a damaged one
            gaps = []
            for n in names:
                for s in exp.sequences:
                    if not done(n, s):
                        folder = result_folder(a.results, a.split, n, s.name)
                        gaps.append(f"{n}/{s.name}" + (f" (no {s.name}_status.txt: unfinished or damaged)"
                                                        if folder.is_dir() else ""))
            shown = "; ".join(gaps[:4]) + (f"; and {len(gaps) - 4} more" if len(gaps) > 4 else "")
            notes.append(f"scored {len(have)} of the split's {len(exp.sequences)} sequences (those every "
                         f"compared run has; --sequence to choose); missing: {shown}")
        exp.sequences = have
    if a.baseline is not None and a.baseline not in names:
        raise ValueError(f"--baseline {a.baseline} is not one of the compared runs: {', '.join(names)}")
    if a.tracker_boxes:
        notes.append("scored: the 2D trackers' own boxes (--tracker-boxes), 2D only")
    plots = not a.no_plots
    if plots and not _have_module("matplotlib"):   # the lean install: scores first, plots optional
        plots = False
        notes.append("no plots: matplotlib is not installed (pip install 'track3d[plot]'; --no-plots "
                     "says this is meant)")
    report = exp.report(names, plots=plots, trajectories=a.trajectories,
                        worst_first=a.trajectories_of == "worst", baseline=a.baseline)
    if notes:   # into report.json as well
        report["warnings"] = notes + report.get("warnings", [])
        write_json(Path(a.out) / "report.json", report)
    per_seq = sequence_table(report)
    if per_seq:   # written before anything is printed: a reader that leaves (`| head`) loses no file
        (Path(a.out) / "sequences.txt").write_text(per_seq + "\n")
    print(summary_table(report))
    axes = axis_table(report)
    if axes:
        print(axes)
    sure = paired_table(report)
    if sure:
        print(sure)
    where = condition_table(report)
    if where:
        print(where)
    if per_seq and a.per_sequence:
        print(per_seq)
    for w in report.get("warnings", []):
        print(f"track3d eval: WARNING: {w}", file=sys.stderr)
    print(f"report: {Path(a.out) / 'report.json'}")
    if per_seq:
        print(f"per sequence: {Path(a.out) / 'sequences.txt'}")
    for f in report.get("plots", []):
        print(f"plot: {f}")
    return 0


def _cmd_docs(a) -> int:
    from .manual import doc_paths, doc_text

    if a.name is not None:
        sys.stdout.write(doc_text(a.name))
        return 0
    paths = doc_paths()
    if not paths:
        raise ValueError("no documents installed with this track3d (a wheel built without them)")
    for name, path in paths.items():
        print(f"{name:10s} {path}")
    return 0


def _have_module(name: str) -> bool:
    """Whether `import name` would find it (None in sys.modules counts as absent, as import does)."""
    import importlib.util

    if name in sys.modules:
        return sys.modules[name] is not None
    return importlib.util.find_spec(name) is not None


def _cmd_trackers(a) -> int:
    from .estimators import available_estimators
    from .trackers2d import TRACKER_NEEDS, available_trackers

    names = available_trackers()
    print("2D trackers:   " + ", ".join(names))
    print("3D estimators: " + ", ".join(available_estimators()))
    for n in names:
        if n in TRACKER_NEEDS:
            print(f"  {n} needs {TRACKER_NEEDS[n]}")
    return 0


DEMO_MOVED = ("the demo simulates its data and lives with the simulator: run `track3d-sim demo` "
              "(pip install 'track3d[sim]')")


def main(argv: list[str] | None = None) -> int:
    """The `track3d` console script; its warnings print as one line (argparsing.one_line_warnings)."""
    from .argparsing import one_line_warnings

    from .argparsing import terminate_as_interrupt

    with one_line_warnings("track3d"), terminate_as_interrupt():
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["demo"]:  # whatever its flags: one line saying where the demo went
        if any(a in ("-h", "--help") for a in argv[1:]):   # asked for help: that line is the help
            print(f"track3d demo: {DEMO_MOVED}")
            return 0
        print(f"track3d demo: error: {DEMO_MOVED}", file=sys.stderr)
        return 2
    args = _parser().parse_args(argv)
    from .dataset import DatasetError
    from .estimators import EstimatorUnavailable
    from .onnxmodel import ModelError
    from .trackers2d import TrackerUnavailable

    try:
        from .plugins import import_plugin

        for mod in list(getattr(args, "plugins_top", []) or []) + list(getattr(args, "plugins", []) or []):
            import_plugin(mod)
        if args.command == "track":
            return _cmd_track(args)
        if args.command == "eval":
            return _cmd_eval(args)
        if args.command == "bench":
            return _cmd_bench(args)
        if args.command == "demo":
            raise RuntimeError(DEMO_MOVED)
        if args.command == "docs":
            return _cmd_docs(args)
        return _cmd_trackers(args)
    except BrokenPipeError as e:   # `track3d eval ... | head`: the reader left, nothing went wrong here
        import os

        if _stdout_closed():
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # no second error at exit's flush
            return 0
        # another pipe (a plug-in's socket to a helper process): an error like any other
        print(f"track3d {args.command}: error: {_plugin_said(e) or e}", file=sys.stderr)
        return 2
    except (DatasetError, TrackerUnavailable, EstimatorUnavailable, ModelError, OSError,
            ValueError, RuntimeError) as e:
        print(f"track3d {args.command}: error: {_plugin_said(e) or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        from .argparsing import interrupt_exit

        how = {"track": "the finished sequences are kept; the same command goes on from the first unfinished one",
               "eval": "no report was written; the same command makes it",
               "bench": "nothing was written; the same command measures again"}.get(args.command, "")
        return interrupt_exit(f"track3d {args.command}", e, how)
    except Exception as e:   # a plug-in's own bug: named in one line; track3d's own keeps its traceback
        said = _plugin_said(e)
        if said is None:
            raise
        print(f"track3d {args.command}: error: {said}", file=sys.stderr)
        return 2


def _stdout_closed() -> bool:
    """Whether stdout is a pipe whose reader has gone (poll says so on its write end); True
    where poll is missing (not POSIX), as any broken pipe was taken before."""
    import io
    import select

    try:
        fd = sys.stdout.fileno()
    except (AttributeError, io.UnsupportedOperation, OSError, ValueError):   # not a file (captured): not it
        return False
    if not hasattr(select, "poll"):
        return True
    p = select.poll()
    p.register(fd, select.POLLOUT)
    # Linux says POLLERR for a pipe without a reader, macOS and the BSDs POLLHUP
    return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in p.poll(0))


def _plugin_said(e: BaseException) -> str | None:
    """'the plug-in raised <Type> at file.py:LINE in FUNC: <message>' when `e` came out of a
    plug-in's code (a RuntimeError of its own had read as track3d's), else None."""
    from .plugins import plugin_frame

    where = plugin_frame(e)
    return None if where is None else f"the plug-in raised {type(e).__name__} at {where}: {e}"


if __name__ == "__main__":
    sys.exit(main())
