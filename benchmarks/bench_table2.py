"""Paper Table 2 reproduction, fusion on / off, and Track3D under every 2D tracker (Fig. 15 / 16).

One run, one table, every configuration a `TrackerSpec` run through ONE `Experiment` (the
restart protocol of paper III-C) on the same sequences of a dataset split:

  SiamFC-<v> (2D)                       siamfc[-edge] + baseline, fusion off: its 2D numbers
  A3BoxNet (oracle 2D)                  oracle + a3boxnet, fusion off
  Baseline 3D (oracle 2D)               oracle + baseline, fusion off
  3D baseline: SiamFC-<v> + min box     siamfc[-edge] + baseline + fusion
  Track3D: SiamFC-<v> + A3BoxNet        siamfc[-edge] + a3boxnet + fusion
  Track3D no fusion                     siamfc[-edge] + a3boxnet, fusion off

for v in (edge, faithful), beside the paper's numbers (PAPER). A configuration that appears
twice is run once. Then fusion on vs off (does fusion improve AO_2d, as the paper claims?)
and the sweep: <2D tracker> + a3boxnet + fusion for every --trackers entry (Fig. 15: 3D
success / precision curves and AO per tracker; Fig. 16: 3D accuracy against 2D accuracy).

Caveat measured here, not assumed: with fusion off the 2D tracker never sees the estimator
(Track3D.update calls tracker.correct() only when fusion is on), but the restart protocol
re-initialises the tracker after a zero-3D-IoU frame, and that depends on the estimator.
So "2D alone" under restarts is not estimator-free. --ope (default on) therefore also runs
a second Experiment without restarts (one-pass evaluation, as the 2D toolkits and the
paper's SiamFC row): SiamFC-<v> + baseline without fusion (the 2D tracker alone, exactly)
and with fusion, and + a3boxnet with fusion: the clean fusion on / off comparison.

    nice python benchmarks/bench_table2.py --data data/small --split test

Writes <out>/table2.json (CPU model, dataset size, every row's metrics), <out>/table2.md
(the tables, also printed), <out>/fig15_sweep.png, <out>/fig16_3d_vs_2d.png, the
Experiment's results (<out>/results, <out>/results_ope) and reports (<out>/report*/:
report.json, success / precision curves, 3D trajectories). Default out:
./bench-results/table2 (--out benchmarks/results/table2 for the committed tables). Missing models (no shipped SiamFC / A3BoxNet ONNX, no NanoTrack
peer model) make their rows "skipped" with the reason, unless --no-skip-missing.
"""
from __future__ import annotations

import argparse
import math
import sys
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from benchlib.output import add_out_argument, relative_to
from benchlib.paper import COLUMNS as PAPER_COLUMNS
from benchlib.paper import TABLE2 as PAPER
from benchlib.paper import fusion_gain
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, hidden_alias, run_main, thread_count
from track3d.evaluation.tables import columns
from track3d.jsonable import write_json
from track3d.machine import pin_threads
from track3d.table_text import cell as _f

DEFAULT_TRACKERS = ("siamfc-edge", "siamfc", "nano", "kcf", "csrt", "mosse", "mil")
VARIANTS = (("edge", "siamfc-edge"), ("faithful", "siamfc"))
OPENCV_LIKE = ("kcf", "csrt", "mosse", "mil", "medianflow", "boosting", "tld", "nano")


def log(msg: str, quiet: bool = False) -> None:
    if not quiet:
        print(msg, file=sys.stderr, flush=True)


def pin(threads: int) -> str:
    """1 thread: the process pinned to one core (the project's target); OpenCV follows --threads."""
    cpus = pin_threads(threads)
    return f"pinned to CPU(s) {', '.join(map(str, cpus))}" if threads == 1 and cpus else "not pinned"


# --- the plan ------------------------------------------------------------------------------------

@dataclass
class Row:
    """One table row: which run (experiment, run name) and how to read it."""

    label: str
    run: str                  # run name (result folder)
    exp: str                  # "main" (restarts) or "ope" (no restarts)
    kind: str                 # "2d": 2D numbers only; "oracle": 3D numbers only; "full": all
    paper: str | None = None  # PAPER key printed after this row's group
    group: str = ""
    short: str = ""           # legend label in the curve plots ("" = not plotted)


def make_spec(tracker: str, estimator: str, fusion: bool, args):
    from track3d.evaluation import TrackerSpec

    topts, name = {}, None
    if tracker in OPENCV_LIKE and args.opencv_correct != "none":
        topts["correct"] = args.opencv_correct
        name = f"{tracker}+{estimator}" + ("" if fusion else "-nofusion") + f"-{args.opencv_correct}"
    return TrackerSpec(tracker, estimator, fusion=fusion, threads=args.threads, tracker_options=topts, name=name)


def plan(args):
    """-> (runs {(exp, name): spec}, table rows, fusion comparisons, sweep {(tracker, est): name})."""
    runs: dict[tuple[str, str], object] = {}

    def add(exp: str, tracker: str, estimator: str, fusion: bool) -> str:
        spec = make_spec(tracker, estimator, fusion, args)
        runs.setdefault((exp, spec.label), spec)
        return spec.label

    rows: list[Row] = []
    fusion_cmp: list[dict] = []
    variants = [v for v in VARIANTS if v[0] in args.variants]
    for v, t in variants:
        rows.append(Row(f"SiamFC-{v} (2D)", add("main", t, "baseline", False), "main", "2d", "SiamFC", "SiamFC"))
    if args.ope:
        for v, t in variants:
            rows.append(Row(f"SiamFC-{v} (2D, no restarts)", add("ope", t, "baseline", False), "ope", "2d",
                            "SiamFC", "SiamFC"))
    rows.append(Row("A3BoxNet (oracle 2D)", add("main", "oracle", "a3boxnet", False), "main", "oracle",
                    "A3BoxNet", "A3BoxNet", "A3BoxNet (oracle 2D)"))
    rows.append(Row("Baseline 3D (oracle 2D)", add("main", "oracle", "baseline", False), "main", "oracle",
                    None, "Baseline 3D (oracle 2D)", "min box (oracle 2D)"))
    for v, t in variants:
        rows.append(Row(f"3D baseline: SiamFC-{v} + min box + fusion", add("main", t, "baseline", True), "main",
                        "full", "3D Tracking Baseline", "3D Tracking Baseline", f"3D baseline (SiamFC-{v})"))
    for v, t in variants:
        rows.append(Row(f"Track3D: SiamFC-{v} + A3BoxNet + fusion", add("main", t, "a3boxnet", True), "main",
                        "full", "Track3D", "Track3D", f"Track3D (SiamFC-{v})"))
    for v, t in variants:
        rows.append(Row(f"Track3D no fusion: SiamFC-{v} + A3BoxNet", add("main", t, "a3boxnet", False), "main",
                        "full", None, "Track3D no fusion"))
    # Fusion on / off: with restarts for both estimators, and without restarts (OPE).
    for v, t in variants:
        for est in ("baseline", "a3boxnet"):
            fusion_cmp.append({"tracker": f"SiamFC-{v}", "estimator": est, "protocol": "restarts",
                               "off": ("main", add("main", t, est, False)), "on": ("main", add("main", t, est, True))})
        if args.ope:
            off = ("ope", add("ope", t, "baseline", False))  # with OPE, 2D alone is estimator-free
            for est in ("baseline", "a3boxnet"):
                fusion_cmp.append({"tracker": f"SiamFC-{v}", "estimator": est, "protocol": "no restarts",
                                   "off": off, "on": ("ope", add("ope", t, est, True))})
    sweep = {}
    for est in args.sweep_estimators:
        for t in args.trackers:
            sweep[(t, est)] = add("main", t, est, True)
    return runs, rows, fusion_cmp, sweep


# --- running --------------------------------------------------------------------------------------

def fps_row(kind: str, summary: dict, stage_ms: dict) -> tuple[float, str]:
    """The FPS a row is compared on: the module's own stage for module rows, else the loop."""
    if kind == "2d":
        ms, basis = stage_ms.get("track2d", float("nan")), "2D tracker stage only"
    elif kind == "oracle":
        ms, basis = stage_ms.get("box3d", float("nan")), "3D estimator stage only"
    else:
        return summary.get("fps", float("nan")), "whole loop (tracker time, I/O excluded)"
    return (1e3 / ms if ms and math.isfinite(ms) and ms > 0 else float("nan")), basis


# --- tables ---------------------------------------------------------------------------------------

# the evaluation table's columns, FPS as the row's own basis (fps_row)
TABLE_COLS = columns("ao_2d", "ace_2d", "ao_bev", "ao_3d", "ace_3d", "sr50_3d", "restarts") + (("FPS", "fps_row", "{:.1f}"),)
SHOWN = {"2d": {"ao_2d", "ace_2d", "restarts", "fps_row"},
         "oracle": {"ao_bev", "ao_3d", "ace_3d", "sr50_3d", "restarts", "fps_row"}}


def table2_md(rows: list[Row], records: list[dict]) -> str:
    """Our rows grouped as the paper's, each group followed by the paper's row (italics)."""
    lines = ["| row | " + " | ".join(c[0] for c in TABLE_COLS) + " |", "|" + "---|" * (len(TABLE_COLS) + 1)]
    for i, (r, rec) in enumerate(zip(rows, records)):
        if rec["status"] != "ok":
            lines.append(f"| {r.label} | *{rec['status']}* |" + " |" * (len(TABLE_COLS) - 1))
        else:
            m = rec["metrics"]
            cells = [_f(m.get(k), fmt) if r.kind == "full" or k in SHOWN[r.kind] else "-"
                     for _, k, fmt in TABLE_COLS]
            lines.append(f"| {r.label} | " + " | ".join(cells) + " |")
        last = i + 1 == len(rows) or rows[i + 1].group != r.group
        if last and r.paper:
            p = PAPER[r.paper]
            cells = [_f(p["AO_2d"]), _f(p["ACE_2d(px)"], "{:.2f}"), _f(p["AO_bev"]), _f(p["AO_3d"]),
                     _f(p["ACE_3d(m)"]), "-", "-", _f(p["FPS"], "{:.1f}")]
            lines.append(f"| *paper: {r.paper}* | " + " | ".join(f"*{c}*" if c != "-" else c for c in cells) + " |")
    return "\n".join(lines)


def fusion_md(fusion_rows: list[dict]) -> str:
    lines = ["| 2D tracker | estimator | protocol | AO_2d off | AO_2d on | gain | gain % | AO_2d raw (on) | "
             "ACE_2d off | ACE_2d on | AO_3d off | AO_3d on | restarts off | restarts on |",
             "|" + "---|" * 14]
    for f in fusion_rows:
        if f["status"] != "ok":
            lines.append(f"| {f['tracker']} | {f['estimator']} | {f['protocol']} | *{f['status']}* |"
                         + " |" * 10)
            continue
        off, on = f["off_metrics"], f["on_metrics"]
        lines.append(f"| {f['tracker']} | {f['estimator']} | {f['protocol']} | {_f(off['ao_2d'])} | "
                     f"{_f(on['ao_2d'])} | {_f(f['ao_2d_gain'], '{:+.3f}')} | {_f(f['ao_2d_gain_pct'], '{:+.1f}')} | "
                     f"{_f(on.get('ao_2d_raw'))} | "
                     f"{_f(off['ace_2d'], '{:.2f}')} | {_f(on['ace_2d'], '{:.2f}')} | "
                     f"{_f(off['ao_3d']) if f['off_estimator'] == f['estimator'] else '-'} | "
                     f"{_f(on['ao_3d'])} | {off['restarts']} | {on['restarts']} |")
    siamfc = PAPER["SiamFC"]
    for row, est in (("3D Tracking Baseline", "baseline"), ("Track3D", "a3boxnet")):
        p = PAPER[row]
        gain, pct = fusion_gain(row)
        cells = [f"*{siamfc['AO_2d']:.3f}*", f"*{p['AO_2d']:.3f}*", f"*{gain:+.3f}*", f"*{pct:+.1f}*", "-",
                 f"*{siamfc['ACE_2d(px)']:.2f}*", f"*{p['ACE_2d(px)']:.2f}*", "-", f"*{p['AO_3d']:.3f}*", "-", "-"]
        label = "3D baseline" if est == "baseline" else "Track3D"
        lines.append(f"| *paper: SiamFC -> {label}* | {est} | ? | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _ok(v) -> bool:
    return v is not None and isinstance(v, (int, float)) and math.isfinite(v)


def sweep_md(sweep_rows: list[dict]) -> str:
    lines = ["| 2D tracker | estimator | AO_2d | AO_2d raw | ACE_2d (px) | AO_bev | AO_3d | ACE_3d (m) | SR50_3d | "
             "restarts | FPS |", "|" + "---|" * 11]
    for s in sweep_rows:
        if s["status"] != "ok":
            lines.append(f"| {s['tracker']} | {s['estimator']} | *{s['status']}* |" + " |" * 8)
            continue
        m = s["metrics"]
        lines.append(f"| {s['tracker']} | {s['estimator']} | {_f(m['ao_2d'])} | {_f(m.get('ao_2d_raw'))} | "
                     f"{_f(m['ace_2d'], '{:.2f}')} | {_f(m['ao_bev'])} | {_f(m['ao_3d'])} | "
                     f"{_f(m['ace_3d'])} | {_f(m['sr50_3d'])} | {m['restarts']} | {_f(m['fps'], '{:.1f}')} |")
    return "\n".join(lines)


# --- plots ----------------------------------------------------------------------------------------

def _fit(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3 or np.ptp(x[ok]) < 1e-9:
        return None
    slope, icpt = np.polyfit(x[ok], y[ok], 1)
    r = np.corrcoef(x[ok], y[ok])[0, 1] if np.ptp(y[ok]) > 1e-12 else float("nan")
    return float(slope), float(icpt), float(r)


def _ao_limits(v, pad: float = 0.05) -> tuple[float, float]:
    """Axis limits of AO values (0..1): `pad` beyond the lowest and highest, so that a marker at
    1.0 (or 0) is whole, not cut at the frame; (0, 1) without values."""
    if not len(v):
        return 0.0, 1.0
    return max(-pad, float(np.min(v)) - pad), min(1.0 + pad, float(np.max(v)) + pad)


def _dodge(points, xlim, ylim, near: float = 0.02, step: float = 8.0) -> list[float]:
    """Horizontal offsets in points (1/72 inch) of markers: those that would lie on each other
    (closer than `near` of the axes' span in x and in y, chained) are spread side by side, `step`
    apart around their place, in drawing order; 0 for the others and for non-finite points."""
    n = len(points)
    xy = np.array(points, float).reshape(n, 2)
    uv = (xy - [xlim[0], ylim[0]]) / [max(xlim[1] - xlim[0], 1e-12), max(ylim[1] - ylim[0], 1e-12)]
    ok = np.isfinite(uv).all(axis=1)
    root = list(range(n))

    def find(i):
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if ok[i] and ok[j] and np.all(np.abs(uv[i] - uv[j]) < near):
                root[find(j)] = find(i)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    out = [0.0] * n
    for members in groups.values():
        for k, i in enumerate(members):
            out[i] = (k - (len(members) - 1) / 2.0) * step if len(members) > 1 else 0.0
    return out


def sweep_plots(sweep_rows: list[dict], overall: dict, out: Path, subtitle: str) -> list[Path]:
    """fig15_sweep.png (3D success / precision curves, AO bars per tracker) and fig16_3d_vs_2d.png."""
    from matplotlib.lines import Line2D
    from matplotlib.transforms import ScaledTranslation
    from track3d.evaluation.metrics import CE3D_THRESHOLDS, IOU_THRESHOLDS
    from track3d.evaluation.plots import pyplot

    plt = pyplot()
    ok = [s for s in sweep_rows if s["status"] == "ok"]
    if not ok:
        return []
    ests = sorted({s["estimator"] for s in ok}, key=lambda e: (e != "a3boxnet", e))
    trackers = list(dict.fromkeys(s["tracker"] for s in ok))
    cmap = plt.get_cmap("tab10")
    colour = {t: cmap(k % 10) for k, t in enumerate(trackers)}
    styles = dict(zip(ests, ("-", "--", ":", "-.")))
    multi = len(ests) > 1
    files = []

    # Fig. 15: 3D success and precision curves per 2D tracker, and AO bars.
    rows_a = -(-len(ok) // 2)   # legend rows under (a) and (b)
    fig = plt.figure(figsize=(13, 9 + 0.16 * rows_a))
    gs = fig.add_gridspec(2, 2, height_ratios=[1.15 + 0.07 * rows_a, 1])
    a_s, a_p, a_b = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, :])
    for s in sorted(ok, key=lambda s: -np.nan_to_num(s["metrics"]["ao_3d"], nan=-1)):
        ov = overall[s["run"]]
        lab = s["tracker"] + (f" + {s['estimator']}" if multi else "")
        a_s.plot(IOU_THRESHOLDS, ov.curves["success_3d"], styles[s["estimator"]], color=colour[s["tracker"]],
                 label=f"{lab} [AO {s['metrics']['ao_3d']:.3f}]")
    for s in sorted(ok, key=lambda s: np.nan_to_num(s["metrics"]["ace_3d"], nan=1e9)):
        ov = overall[s["run"]]
        lab = s["tracker"] + (f" + {s['estimator']}" if multi else "")
        a_p.plot(CE3D_THRESHOLDS, ov.curves["precision_3d"], styles[s["estimator"]], color=colour[s["tracker"]],
                 label=f"{lab} [ACE {s['metrics']['ace_3d']:.3f} m]")
    a_s.set(xlabel="3D IoU threshold", ylabel="success rate", title="(a) 3D success plot", xlim=(0, 1),
            ylim=(0, 1.02))
    a_p.set(xlabel="3D centre error threshold (m)", ylabel="precision", title="(b) 3D precision plot",
            xlim=(CE3D_THRESHOLDS[0], CE3D_THRESHOLDS[-1]), ylim=(0, 1.02))
    # the legends under the panels: inside, any corner lies on some run's curve
    for a in (a_s, a_p):
        a.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False)
    x = np.arange(len(ok))
    w = 0.26
    for k, (key, name, c) in enumerate((("ao_2d", "AO_2d (reported, fused)", "#9e9e9e"),
                                        ("ao_bev", "AO_bev", "#1f77b4"), ("ao_3d", "AO_3d", "#d62728"))):
        vals = [float(np.nan_to_num(s["metrics"][key], nan=0.0)) for s in ok]
        bars = a_b.bar(x + (k - 1) * w, vals, w, label=name, color=c)
        for b, v in zip(bars, vals):
            a_b.text(b.get_x() + b.get_width() / 2, v + 0.01, f"{v:.2f}", ha="center", va="bottom", fontsize=7)
    a_b.set_xticks(x, [s["tracker"] + (f"\n+ {s['estimator']}" if multi else "") for s in ok], fontsize=9)
    a_b.set(ylabel="average overlap", ylim=(0, 1.15), xlim=(-0.6, len(ok) - 0.4),
            title="(c) accuracy of Track3D (+ fusion) per 2D tracker")
    a_b.legend(fontsize=8, loc="upper right", ncol=3)
    for a in (a_s, a_p, a_b):
        a.grid(alpha=0.3)
    fig.suptitle(f"Track3D under different 2D trackers (paper Fig. 15); {subtitle}", fontsize=11)
    fig.tight_layout()
    f = out / "fig15_sweep.png"
    fig.savefig(f, dpi=100)
    plt.close(fig)
    files.append(f)

    # Fig. 16: 3D accuracy against 2D accuracy, one colour per 2D tracker, a line fit per estimator.
    fig, ax = plt.subplots(figsize=(8.5, 5.8))
    markers = dict(zip(ests, ("o", "D", "^", "v")))
    fits, allx, ally, marks = [], [], [], []
    for e in ests:
        pts = [s for s in ok if s["estimator"] == e]
        x2 = [s["metrics"]["ao_2d"] for s in pts]
        for key, filled in (("ao_3d", True), ("ao_bev", False)):
            y = [s["metrics"][key] for s in pts]
            marks += [(xv, yv, colour[s["tracker"]], filled, markers[e]) for s, xv, yv in zip(pts, x2, y)]
            allx += x2
            ally += y
            fit = _fit(x2, y)
            if fit:
                xs = np.linspace(np.nanmin(x2), np.nanmax(x2), 10)
                ax.plot(xs, fit[0] * xs + fit[1], "--" if filled else ":", color="grey", lw=1, zorder=2)
                fits.append(Line2D([], [], color="grey", ls="--" if filled else ":",
                                   label=f"fit {key[3:].upper()} ({e}): slope {fit[0]:.2f}, r {fit[2]:.2f}"))
    fx, fy = np.asarray(allx, float), np.asarray(ally, float)
    fx, fy = fx[np.isfinite(fx)], fy[np.isfinite(fy)]
    xlim, ylim = _ao_limits(fx), _ao_limits(np.concatenate([fx, fy]) if len(fy) else fy)
    ax.plot([0, 1], [0, 1], color="lightgrey", lw=1, zorder=0)
    ax.set(xlim=xlim, ylim=ylim)
    for a, lim in ((ax.xaxis, xlim), (ax.yaxis, ylim)):   # no tick outside 0..1 in the margins
        a.set_ticks([t for t in a.get_ticklocs() if max(0.0, lim[0]) - 1e-9 <= t <= min(1.0, lim[1]) + 1e-9])
    shift = _dodge([(m[0], m[1]) for m in marks], xlim, ylim)
    for (xv, yv, c, filled, mk), dx in zip(marks, shift):
        # markers at one place (equal scores) side by side, dx points apart; never cut at the frame
        ax.scatter([xv], [yv], s=70 if filled else 45, marker=mk, edgecolors=c, facecolors=c if filled else "none",
                   linewidths=1.5, zorder=3, clip_on=False,
                   transform=ax.transData + ScaledTranslation(dx / 72.0, 0.0, fig.dpi_scale_trans))
    ax.set(xlabel="AO_2d of the Track3D run (reported, fused box)"
                  + ("\n(markers of equal scores drawn side by side)" if any(shift) else ""),
           ylabel="3D accuracy (AO)", title=f"3D accuracy against 2D accuracy (paper Fig. 16)\n{subtitle}")
    ax.grid(alpha=0.3)
    keys = [Line2D([], [], ls="", marker=markers[e], color="black", markerfacecolor=fc, label=f"{m}, {e}")
            for e in ests for m, fc in (("AO_3d", "black"), ("AO_bev", "none"))]
    keys += [Line2D([], [], color="lightgrey", label="y = x")] + fits
    trk = [Line2D([], [], ls="", marker="s", color=colour[t], label=t) for t in trackers]
    leg = ax.legend(handles=trk, title="2D tracker", fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.add_artist(leg)
    ax.legend(handles=keys, fontsize=7, loc="lower left", bbox_to_anchor=(1.01, 0.0))
    fig.tight_layout()
    f = out / "fig16_3d_vs_2d.png"
    fig.savefig(f, dpi=100)
    plt.close(fig)
    files.append(f)
    return files


# --- main -----------------------------------------------------------------------------------------

def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--data", required=True, help="dataset root (the folder with dataset.json)")
    ap.add_argument("--split", default="test", help="dataset split (default: test)")
    add_out_argument(ap, "table2", committed="benchmarks/results/table2")
    ap.add_argument("--threads", type=thread_count, default=1,
                    help="CPU threads of the ONNX models and OpenCV (default 1: the process is pinned to one core)")
    ap.add_argument("--max-sequences", type=bounded(int, 0), default=0,
                    help="only the first N sequences of the split (0: all)")
    hidden_alias(ap, "--max-seqs", "max_sequences", type=bounded(int, 0))
    ap.add_argument("--max-frames", type=bounded(int, 0), default=0, help="only the first N frames of each sequence (0: all)")
    ap.add_argument("--trackers", nargs="+", default=list(DEFAULT_TRACKERS), metavar="NAME",
                    help="2D trackers of the Fig. 15/16 sweep (default: %(default)s)")
    ap.add_argument("--sweep-estimators", nargs="+", default=["a3boxnet"], metavar="NAME",
                    help="3D estimators of the sweep (default: a3boxnet; add baseline to compare)")
    ap.add_argument("--variants", nargs="+", default=["edge", "faithful"], choices=["edge", "faithful"],
                    help="SiamFC variants of the Table 2 rows (default: both)")
    ap.add_argument("--ope", action=argparse.BooleanOptionalAction, default=True,
                    help="also run SiamFC without restarts (one-pass): the estimator-free 2D row and a clean "
                         "fusion on/off comparison (default: on)")
    ap.add_argument("--opencv-correct", choices=("none", "reinit"), default="none",
                    help="how OpenCV trackers (and NanoTrack) take the fused box: none (default: ignored) "
                         "or reinit (re-initialise on it every frame)")
    ap.add_argument("--restart-skip", type=int, default=1,
                    help="re-initialise this many frames after a zero-3D-IoU frame (default 1: the next)")
    ap.add_argument("--skip-missing", action=argparse.BooleanOptionalAction, default=True,
                    help="report a tracker / estimator whose model is missing as skipped (default); "
                         "--no-skip-missing: exit 2 instead")
    ap.add_argument("--resume", action="store_true",
                    help="keep sequences that already have results in <out> (same --max-frames!) instead of "
                         "re-running them")
    ap.add_argument("--trajectories", type=int, default=2, help="sequences with a 3D trajectory plot (2)")
    ap.add_argument("--quiet", action="store_true", help="no progress output on stderr")
    return ap


def unknown_names(a) -> str | None:
    """The error text when a --trackers or --sweep-estimators name is not registered."""
    from track3d.estimators import available_estimators
    from track3d.trackers2d import available_trackers

    for t in a.trackers:
        if t.lower() not in available_trackers():
            return f"unknown 2D tracker {t!r} (known: {', '.join(available_trackers())})"
    for e in a.sweep_estimators:
        if e.lower() not in available_estimators():
            return f"unknown estimator {e!r} (known: {', '.join(available_estimators())})"
    return None


def experiments(a, out: Path) -> dict:
    """{"main": restarts, "ope": one pass (with --ope)} on the same sequences and frames."""
    from track3d.evaluation import Experiment

    max_frames = a.max_frames or None
    exps = {"main": Experiment(a.data, a.split, out / "results", out / "report", max_frames=max_frames,
                               restart=True, restart_skip=a.restart_skip, max_sequences=a.max_sequences or None)}
    if a.ope:
        exps["ope"] = Experiment(a.data, a.split, out / "results_ope", out / "report_ope", max_frames=max_frames,
                                 sequences=[s.name for s in exps["main"].sequences], restart=False)
    return exps


def run_all(runs: dict, exps: dict, status: dict, reason: dict, a) -> dict:
    """Run every available configuration (status / reason filled in); -> wall seconds per run."""
    import time

    todo = [k for k in runs if k not in status]
    wall = {}
    for i, key in enumerate(todo):
        exp_key, name = key
        t0 = time.perf_counter()
        log(f"[{i + 1}/{len(todo)}] {name} ({'restarts' if exp_key == 'main' else 'no restarts'}) ...", a.quiet)
        try:
            exps[exp_key].run(runs[key], name=name, overwrite=not a.resume, quiet=a.quiet)
            status[key] = "ok"
        except Exception as e:  # one broken configuration must not lose the others
            status[key], reason[key] = "failed", f"{type(e).__name__}: {e}"
            log(traceback.format_exc(), a.quiet)
        wall[key] = time.perf_counter() - t0
        log(f"[{i + 1}/{len(todo)}] {name}: {status[key]} in {wall[key]:.1f} s"
            + (f" ({reason[key]})" if key in reason else ""), a.quiet)
    return wall


def score_all(runs: dict, exps: dict, status: dict, wall: dict) -> tuple[dict, dict, dict]:
    """One report per experiment (report.json) plus the 2D tracker's own (pre-fusion) scores:
    -> (metrics, OverallScore, report paths), keyed by (experiment, run name)."""
    from track3d.evaluation.metrics import average_scores

    metrics, overall, reports = {}, {}, {}
    for exp_key, exp in exps.items():
        done = [k[1] for k in runs if k[0] == exp_key and status[k] == "ok"]
        if not done:
            continue
        rep = exp.report(done, plots=False)
        reports[exp_key] = str(exp.report_dir / "report.json")
        for name in done:
            t = rep["trackers"][name]
            raw = average_scores(exp.score(name, raw=True)).values
            metrics[(exp_key, name)] = {**t["overall"], "ao_2d_raw": raw["ao_2d"], "ace_2d_raw": raw["ace_2d"],
                                        "sr50_2d_raw": raw["sr50_2d"], "stage_ms_mean": t["stage_ms_mean"],
                                        "wall_s": wall.get((exp_key, name))}
            overall[(exp_key, name)] = average_scores(exp.score(name))
    return metrics, overall, reports


def row_records(rows: list[Row], status: dict, reason: dict, metrics: dict) -> list[dict]:
    out = []
    for r in rows:
        key = (r.exp, r.run)
        rec = {"row": r.label, "group": r.group, "run": r.run, "protocol": "restarts" if r.exp == "main" else
               "no restarts", "kind": r.kind, "paper_row": r.paper, "status": status[key],
               "reason": reason.get(key)}
        if status[key] == "ok":
            m = dict(metrics[key])
            m["fps_row"], m["fps_basis"] = fps_row(r.kind, m, m["stage_ms_mean"])
            rec["metrics"] = m
        out.append(rec)
    return out


def fusion_records(fusion_cmp: list[dict], runs: dict, status: dict, reason: dict, metrics: dict) -> list[dict]:
    out = []
    for f in fusion_cmp:
        rec = {k: f[k] for k in ("tracker", "estimator", "protocol")}
        rec["off"], rec["on"] = f["off"][1], f["on"][1]
        rec["off_estimator"] = runs[f["off"]].estimator
        bad = [k for k in (f["off"], f["on"]) if status[k] != "ok"]
        if bad:
            rec["status"], rec["reason"] = status[bad[0]], reason.get(bad[0])
        else:
            rec["status"] = "ok"
            off, on = rec["off_metrics"], rec["on_metrics"] = metrics[f["off"]], metrics[f["on"]]
            gain = on["ao_2d"] - off["ao_2d"] if _ok(on["ao_2d"]) and _ok(off["ao_2d"]) else float("nan")
            rec["ao_2d_gain"] = gain
            rec["ao_2d_gain_pct"] = 100 * gain / off["ao_2d"] if _ok(gain) and off["ao_2d"] > 0 else float("nan")
        out.append(rec)
    return out


def markdown(a, seqs, n_frames: int, pinned: str, rows, row_recs, fusion_rows, sweep_rows, status, reason) -> str:
    from track3d.machine import cpu_name

    header = (f"CPU: {cpu_name()}; {a.threads} thread(s), {pinned}. Data: {a.data} split "
              f"`{a.split}`: {len(seqs)} sequences, {n_frames} frames"
              + (f" (first {a.max_frames} per sequence)" if a.max_frames else "")
              + f". Protocol: restart {a.restart_skip} frame(s) after a zero 3D IoU (paper III-C); "
                "*no restarts* rows: one-pass. Paper numbers in italics (i9-9900K + RTX 2080Ti).")
    notes = ("FPS: tracker time with I/O excluded, 1 CPU thread here vs the paper's GPU; for the 2D rows the 2D "
             "tracker stage alone, for the oracle rows the 3D estimator stage alone, else the whole loop. "
             "2D rows show only 2D numbers and oracle rows only 3D numbers. 'SiamFC (2D)' under restarts is "
             "siamfc + baseline without fusion: the tracker never sees the estimator, but restarts (zero 3D IoU) "
             "depend on it; the *no restarts* row is the 2D tracker alone, exactly. OpenCV trackers ignore the "
             f"fused box (correct={a.opencv_correct!r}); SiamFC takes it as its next state.")
    md = "\n\n".join([
        "# Table 2 reproduction", header,
        "## Table 2: ours beside the paper", table2_md(rows, row_recs), notes,
        "## Fusion on vs off: does 2D-3D fusion improve AO_2d?", fusion_md(fusion_rows),
        "'AO_2d raw (on)': the 2D tracker's own box in the fused run (for SiamFC it follows the fused state). "
        "Under restarts the two runs restart on different frames, so their AO_2d also differ by the restarts; "
        "the *no restarts* rows compare the same tracker with and without fusion on identical input.",
        "## Track3D under each 2D tracker (Fig. 15 / Fig. 16)", sweep_md(sweep_rows),
    ])
    why_runs: dict[str, list[str]] = {}
    for k, why in reason.items():
        why_runs.setdefault(f"{status[k]}: {why}", []).append(f"`{k[1]}`" + (" (no restarts)" if k[0] == "ope" else ""))
    if why_runs:
        md += "\n\nSkipped or failed runs:\n\n" + "\n".join(
            f"- {why}: {', '.join(sorted(ns))}" for why, ns in sorted(why_runs.items()))
    return md


def all_plots(a, out: Path, main_exp, seqs, rows, overall: dict, sweep_rows, subtitle: str) -> list[Path]:
    """The toolkit's curve and trajectory plots of the table rows and the sweep, and Fig. 15 / 16."""
    from track3d.evaluation import plots as P

    plots = []
    curve_set = {r.short: overall[(r.exp, r.run)] for r in rows if r.short and (r.exp, r.run) in overall}
    if curve_set:
        plots += P.curve_plots(curve_set, out / "report" / "table2_plots")
    # 3D trajectories (Fig. 12): Track3D against the 3D baseline, first SiamFC variant.
    traj = list(dict.fromkeys(r.run for r in rows if r.short and (r.exp, r.run) in overall and r.kind == "full"
                              and a.variants[0] in r.short))
    if traj and a.trajectories > 0:
        plots += P.trajectory_plots(main_exp, traj, [s.name for s in seqs[: a.trajectories]],
                                    out / "report" / "table2_plots")
    ok = [s for s in sweep_rows if s["status"] == "ok"]
    sw = {s["tracker"] + (f"+{s['estimator']}" if len(a.sweep_estimators) > 1 else ""): overall[("main", s["run"])]
          for s in ok}
    if sw:
        plots += P.curve_plots(sw, out / "report" / "sweep_plots")
    return plots + sweep_plots(sweep_rows, {s["run"]: overall[("main", s["run"])] for s in ok}, out, subtitle)


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    from track3d.dataset import DatasetError

    bad = unknown_names(a)
    if bad:
        print(f"bench_table2: error: {bad}", file=sys.stderr)
        return 2
    out = Path(a.out)
    try:
        exps = experiments(a, out)
    except DatasetError as e:
        print(f"bench_table2: error: {e}", file=sys.stderr)
        return 2
    seqs = exps["main"].sequences
    n_frames = sum(len(s) if not a.max_frames else min(len(s), a.max_frames) for s in seqs)
    pinned = pin(a.threads)
    runs, rows, fusion_cmp, sweep = plan(a)
    log(f"{len(seqs)} sequences, {n_frames} frames of {a.data}/{a.split}; {len(runs)} distinct runs; "
        f"{a.threads} thread(s), {pinned}", a.quiet)
    rec = start_record("paper Table 2, fusion on/off, Fig. 15/16 sweep", threads=a.threads, pinning=pinned,
                       data=a.data, split=a.split)

    # Availability first: a missing model is known before any work.
    status: dict[tuple[str, str], str] = {}   # ok | skipped | failed
    reason: dict[tuple[str, str], str] = {}
    for key, spec in runs.items():
        why = spec.unavailable(seqs[0])
        if why is not None:
            if not a.skip_missing:
                print(f"bench_table2: error: {spec.label}: {why}", file=sys.stderr)
                return 2
            status[key], reason[key] = "skipped", why
            log(f"skip {key[1]} ({key[0]}): {why}", a.quiet)
    wall = run_all(runs, exps, status, reason, a)
    metrics, overall, reports = score_all(runs, exps, status, wall)
    row_recs = row_records(rows, status, reason, metrics)
    fusion_rows = fusion_records(fusion_cmp, runs, status, reason, metrics)
    sweep_rows = [{"tracker": t, "estimator": e, "run": name, "status": status[("main", name)],
                   "reason": reason.get(("main", name)), "metrics": metrics.get(("main", name))}
                  for (t, e), name in sweep.items()]
    md = markdown(a, seqs, n_frames, pinned, rows, row_recs, fusion_rows, sweep_rows, status, reason)
    plots = []
    try:
        plots = all_plots(a, out, exps["main"], seqs, rows, overall, sweep_rows,
                          f"{a.split}: {len(seqs)} seq, {n_frames} frames")
    except RuntimeError as e:  # no matplotlib
        log(f"no plots: {e}", a.quiet)
    rec.update(dataset={"sequences": len(seqs), "frames": n_frames, "max_frames": a.max_frames or None,
                        "sequence_names": [s.name for s in seqs]},
               protocol={"restart": True, "restart_skip": a.restart_skip, "ope_runs": a.ope,
                         "opencv_correct": a.opencv_correct},
               paper=PAPER, paper_columns=PAPER_COLUMNS, rows=row_recs, fusion=fusion_rows, sweep=sweep_rows,
               runs={f"{k[0]}/{k[1]}": {"spec": _spec_dict(runs[k]), "status": status[k], "reason": reason.get(k),
                                         "wall_s": wall.get(k)} for k in runs},
               # relative to the output folder: an absolute --out must not put machine paths in the record
               reports={k: relative_to(v, out) for k, v in reports.items()},
               plots=[relative_to(p, out) for p in plots])
    write_json(out / "table2.json", finish_record(rec))
    (out / "table2.md").write_text(md + "\n")
    print(md)
    log(f"wrote {out / 'table2.json'}, {out / 'table2.md'}" + "".join(f", {p}" for p in plots
                                                                    if p.parent == out), a.quiet)
    return 1 if any(s.startswith("failed") for s in status.values()) else 0


def _spec_dict(spec) -> dict:
    d = asdict(spec)
    d["label"] = spec.label
    return d


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_table2.py"))
