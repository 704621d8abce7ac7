"""`track3d-sim demo`: simulate a small test set, track it, evaluate, write everything, say where.

It lives in the simulator's package because it simulates its data (the runtime never imports
the simulator; this module imports both). Steps: (1) render a test-only dataset
(`generate`); (2) run Track3D with the shipped
models (SiamFC edge + A3BoxNet), or, if a model cannot be loaded (a broken install), the
OpenCV CSRT tracker / the baseline box estimator in its place, with a warning that says so; (3) evaluate under the restart protocol and
print a Table-2-style summary; (4) write report.json, summary.json, success / precision
plots, 3D trajectory plots and an overlay GIF of the first sequence.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ["add_arguments", "run_demo", "pick_models"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="track3d-demo", help="output folder (default ./track3d-demo)")
    from .generate import PRESETS

    p.add_argument("--preset", choices=sorted(PRESETS), default="small",
                   help="simulator preset for camera and scenes (default small)")
    p.add_argument("--sequences", type=int, default=2, help="test sequences to simulate (default 2)")
    p.add_argument("--frames", type=int, default=40, help="frames per sequence (default 40)")
    from track3d.argparsing import thread_count

    p.add_argument("--threads", type=thread_count, default=1, help="CPU threads of the models (default 1)")
    p.add_argument("--tracker", help="2D tracker (default: the shipped EdgeTrack, else csrt)")
    p.add_argument("--estimator", help="3D box estimator (default: the shipped A3BoxNet, else baseline)")
    p.add_argument("--seed", type=int, default=0, help="simulator seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    from track3d.argparsing import hidden_alias

    hidden_alias(p, "--no-progress", "quiet", action="store_true")


# What `track3d-sim demo` imports beyond the runtime (module -> the extra that installs it).
DEMO_NEEDS = {"trimesh": "sim", "PIL": "sim", "scipy": "sim", "tqdm": "sim", "matplotlib": "plot"}


def missing_demo_modules() -> list[str]:
    """The modules the demo needs that are not installed."""
    import importlib.util

    return [m for m in DEMO_NEEDS if importlib.util.find_spec(m) is None]


def pick_models(tracker: str | None, estimator: str | None, threads: int) -> tuple[str, str, list[str]]:
    """The tracker and estimator names to use, and warnings for every fallback taken. A name
    no registry knows is the registry's ValueError (called before simulating anything)."""
    from track3d.estimators import available_estimators, create_estimator
    from track3d.trackers2d import available_trackers, create_tracker

    if tracker is not None and str(tracker).lower() not in available_trackers():
        create_tracker(tracker)          # raises "unknown 2D tracker ...; available: ..."
    if estimator is not None and str(estimator).lower() not in available_estimators():
        create_estimator(estimator)      # raises "unknown 3D box estimator ...; available: ..."
    warnings = []
    if tracker is None:
        try:
            create_tracker("edgetrack", threads=threads)
            tracker = "edgetrack"
        except Exception as e:  # a missing or unreadable shipped model: fall back, loudly
            tracker = "csrt"
            warnings.append(f"no shipped EdgeTrack ({e}); using OpenCV's CSRT as the 2D tracker")
    if estimator is None:
        try:
            create_estimator("a3boxnet", threads=threads)
            estimator = "a3boxnet"
        except Exception as e:
            estimator = "baseline"
            warnings.append(f"no shipped A3BoxNet ({e}); using the baseline (minimum enclosing box)")
    return tracker, estimator, warnings


def _simulate(data: Path, a) -> None:
    if (data / "dataset.json").is_file():
        info = json.loads((data / "dataset.json").read_text())
        gen = info.get("generator", {}).get("settings", info.get("generator", {}))
        print(f"[demo] reusing the simulated data in {data} ({gen.get('preset', '?')} preset)", file=sys.stderr)
        return
    missing = missing_demo_modules()
    if missing:
        raise RuntimeError(f"the demo simulates its data and needs the sim extra: pip install 'track3d[sim]' "
                           f"(missing: {', '.join(missing)})")
    from .generate import generate, make_settings

    settings = make_settings(a.preset, a.seed, train=0, test=a.sequences, frames=a.frames)  # checked, then said
    print(f"[demo] simulating {a.sequences} test sequence(s) x {a.frames} frames ({a.preset} preset) "
          f"into {data} ...", file=sys.stderr)
    generate(settings, data, workers=1, progress=not a.quiet)


def run_demo(a) -> int:
    from track3d.evaluation import Experiment, TrackerSpec
    from track3d.evaluation.tables import axis_table, summary_table
    from track3d.threads import set_threads

    if a.sequences < 1 or a.frames < 2:
        raise ValueError("--sequences must be >= 1 and --frames >= 2")
    set_threads(a.threads)
    out = Path(a.out)
    data = out / "data"
    t0 = time.perf_counter()
    # names first: a typo fails at once, not after minutes of simulation
    tracker, estimator, warnings = pick_models(a.tracker, a.estimator, a.threads)
    _simulate(data, a)
    for w in warnings:
        print(f"[demo] WARNING: {w}", file=sys.stderr)
    spec = TrackerSpec(tracker, estimator, threads=a.threads)
    exp = Experiment(data, "test", out / "results", out / "report", max_frames=a.frames)
    print(f"[demo] tracking with {spec.label} on {len(exp.sequences)} sequence(s), {a.threads} thread(s) ...",
          file=sys.stderr)
    # the demo's results folder is its own output: a re-run after an update (other models, loop
    # options or --frames) replaces it instead of refusing, as an experiment folder would
    folders = exp.run(spec, overlay="gif", overlay_sequences=1, quiet=a.quiet, replace=True)
    report = exp.report([spec.label], plots=True, trajectories=len(exp.sequences))
    ov = report["trackers"][spec.label]["overall"]
    summary = {"tracker": tracker, "estimator": estimator, "threads": a.threads, "warnings": warnings,
               "data": str(data), "sequences": report["sequences"], "frames_per_sequence": a.frames,
               "cpu": report["cpu"],
               **{k: ov.get(k) for k in ("ao_2d", "ace_2d", "ao_bev", "ao_3d", "ace_3d", "sr50_3d", "restarts",
                                         "fps", "fps_e2e", "frames")},
               "stage_ms_mean": report["trackers"][spec.label]["stage_ms_mean"]}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print()
    print(summary_table(report))
    print(axis_table(report))
    print()
    print(f"data:        {data}")
    print(f"results:     {folders[0].parent}")
    overlays = sorted(folders[0].glob("*_overlay.*"))
    if overlays:
        print(f"overlay:     {overlays[0]}  (green: ground truth, yellow: 2D tracker, red: fused, cyan: 3D box)")
    print(f"report:      {out / 'report' / 'report.json'}")
    print(f"summary:     {out / 'summary.json'}")
    for f in report.get("plots", []):
        print(f"plot:        {f}")
    print(f"(demo took {time.perf_counter() - t0:.0f} s)")
    return 0
