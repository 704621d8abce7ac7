"""The README's result tables, generated from the committed result JSON (one command).

    python benchmarks/readme_tables.py            # print the tables
    python benchmarks/readme_tables.py --check    # exit 1 when README.md differs from the JSON
    python benchmarks/readme_tables.py --write    # update the marked sections of README.md

Each table sits in README.md between ``<!-- readme_tables.py: NAME -->`` and
``<!-- /readme_tables.py -->``; its rows name the result file and the row (configuration,
tracker) they come from, so no paragraph has to say which run made which number.
"""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np

from benchlib.paper import TABLE2

from track3d.argparsing import ArgumentParser, run_main
from track3d.table_text import cell, markdown_table

REPO = Path(__file__).resolve().parents[1]
RESULTS = Path("benchmarks") / "results"     # relative to the repository

# the speed table's run, one thread and two (bench_fps.py, the README's "Reproduce" block)
FPS_1T, FPS_2T = "engine/fps_epyc_no_avxvnni_views_engine_1t.json", "engine/fps_epyc_no_avxvnni_views_engine_2t.json"
# (label, result file, configuration, bold)
SPEED_ROWS = (
    ("Track3D default: EdgeTrack + A3BoxNet", FPS_1T, "edgetrack:a3boxnet", True),
    ("SiamFC-edge (the paper's tracker) + A3BoxNet", FPS_1T, "siamfc-edge:a3boxnet", False),
    ("NanoTrack v2 (peer) + A3BoxNet", FPS_1T, "nano:a3boxnet", False),
    ("EdgeTrack + single-frame A3BoxNet (`a3boxnet_narrow.onnx`, the default before: no past views)",
     FPS_1T, "edgetrack:a3boxnet@a3boxnet_narrow.onnx", False),
    ("EdgeTrack + full-width A3BoxNet (`a3boxnet.onnx`)", FPS_1T, "edgetrack:a3boxnet@a3boxnet.onnx", False),
    ("EdgeTrack + baseline box", FPS_1T, "edgetrack:baseline", False),
    ("EdgeTrack + A3BoxNet, 2 threads (both cores)", FPS_2T, "edgetrack:a3boxnet", False),
    ("SiamFC-edge + A3BoxNet, 2 threads", FPS_2T, "siamfc-edge:a3boxnet", False),
)
ENGINE_SPLITS = tuple((s, sp) for s in ("ideal", "flash-lidar", "tof", "stereo") for sp in ("test", "test_unseen"))
# (label, source, row, kind, bold): source "table2*" -> <source>/table2.json's row; "bench_2d" -> its tracker
TABLE2_ROWS = (
    ("**Track3D, ours** (SiamFC-edge + A3BoxNet + fusion)", "table2_edge_current",
     "Track3D: SiamFC-edge + A3BoxNet + fusion", "full", True),
    ("Track3D with the faithful SiamFC (AlexNet, 3 scales; 5 FPS here)", "table2_faithful",
     "Track3D: SiamFC-faithful + A3BoxNet + fusion", "full", False),
    ("paper", "Track3D"),
    ("A3BoxNet alone, oracle 2D box (ours)", "table2_edge_current", "A3BoxNet (oracle 2D)", "oracle", False),
    ("paper", "A3BoxNet"),
    ("3D baseline (SiamFC-edge + minimum enclosing box + fusion)", "table2", "3D baseline: SiamFC-edge + min box + fusion",
     "full", False),
    ("paper", "3D Tracking Baseline"),
    ("SiamFC-edge alone, one pass (2D)", "bench_2d", "siamfc-edge", "2d", False),
    ("SiamFC-faithful alone, one pass (2D)", "bench_2d", "siamfc", "2d", False),
    ("paper", "SiamFC"),
)
# The same rows on the data engine's test split with this release's models (bench_table2.py on
# data/engine-ideal); a key "sweep:<run>" is a row of the Fig. 15 sweep, source "edgetrack_2d" the
# EdgeTrack one-pass 2D evaluation of the same split.
TABLE2_ENGINE_ROWS = (
    ("**Track3D default, ours** (EdgeTrack + A3BoxNet + fusion)", "table2_engine", "sweep:edgetrack+a3boxnet",
     "full", True),
    ("Track3D, the paper's design (SiamFC-edge + A3BoxNet + fusion)", "table2_engine",
     "Track3D: SiamFC-edge + A3BoxNet + fusion", "full", False),
    ("Track3D with the faithful SiamFC (AlexNet, 3 scales)", "table2_engine",
     "Track3D: SiamFC-faithful + A3BoxNet + fusion", "full", False),
    ("NanoTrack v2 (peer) + A3BoxNet + fusion", "table2_engine", "sweep:nano+a3boxnet", "full", False),
    ("paper", "Track3D"),
    ("A3BoxNet alone, oracle 2D box (ours)", "table2_engine", "A3BoxNet (oracle 2D)", "oracle", False),
    ("paper", "A3BoxNet"),
    ("3D baseline (SiamFC-edge + minimum enclosing box + fusion)", "table2_engine",
     "3D baseline: SiamFC-edge + min box + fusion", "full", False),
    ("paper", "3D Tracking Baseline"),
    ("EdgeTrack alone, one pass (2D)", "edgetrack_2d", "edgetrack", "2d", False),
    ("SiamFC-edge alone, one pass (2D)", "table2_engine", "SiamFC-edge (2D, no restarts)", "2d", False),
    ("SiamFC-faithful alone, one pass (2D)", "table2_engine", "SiamFC-faithful (2D, no restarts)", "2d", False),
    ("paper", "SiamFC"),
)
PAPER_LABELS = {"Track3D": "Track3D", "A3BoxNet": "A3BoxNet", "3D Tracking Baseline": "3D tracking baseline",
                "SiamFC": "SiamFC"}


def _load(root: Path, rel: str) -> dict:
    return json.loads((root / RESULTS / rel).read_text())


def _runs(root: Path, rel: str, optional: bool = False) -> dict:
    """The rows of an engine_baseline.py result file by (sensor, split, protocol, tracker); with
    `optional`, none when the file is not there (a run not made yet shows as '-')."""
    if optional and not (root / RESULTS / rel).exists():
        return {}
    return {(r["sensor"], r["split"], r["protocol"], r["tracker"]): r for r in _load(root, rel)["rows"]}


def speed_table(root: Path) -> str:
    rows = []
    for label, rel, config, bold in SPEED_ROWS:
        r = next(x for x in _load(root, rel)["results"] if x["config"] == config and x["backend"] == "onnxruntime"
                 and x["precision"] == "fp32")
        e = r["stages"]["end_to_end"]
        cells = [label, f"{e['median_ms']:.2f} / {e['p99_ms']:.2f}", f"{r['fps_median']:.0f}"]
        rows.append([f"**{c}**" for c in cells] if bold else cells)
    rows.append(["*paper: Track3D (desktop GPU)*", "", f"*{TABLE2['Track3D']['FPS']:.0f}*"])
    return markdown_table(["configuration", "ms (median / p99)", "FPS"], rows)


def engine_table(root: Path) -> str:
    """Before (engine_baseline: the models shipped before the data engine's retraining) and now
    (engine_current: the shipped models), on the same sequences, AO_3d / ACE_3d (m)."""
    before, now = _runs(root, "engine_baseline/engine_baseline.json"), _runs(root, "engine_current/engine_baseline.json")

    def pair(by, key):
        r = by.get(key)
        return "-" if r is None else f"{r['ao_3d']:.3f} / {r['ace_3d']:.3f}"

    rows = []
    for s, sp in ENGINE_SPLITS:
        oracle, siam = (s, sp, "restart", "oracle+a3boxnet"), (s, sp, "onepass", "siamfc-edge+a3boxnet")
        rows.append([s, sp, pair(before, oracle), f"**{pair(now, oracle)}**", pair(before, siam), pair(now, siam),
                     f"**{pair(now, (s, sp, 'onepass', 'edgetrack+a3boxnet'))}**",
                     pair(now, (s, sp, "restart", "edgetrack+a3boxnet")),
                     pair(now, (s, sp, "onepass", "nano+a3boxnet")), pair(now, (s, sp, "restart", "nano+a3boxnet"))])
    table = markdown_table(["depth", "split", "A3BoxNet, oracle 2D: before", "now",
                            "Track3D (SiamFC-edge), one pass: before", "now",
                            "Track3D default (EdgeTrack): one pass", "restart",
                            "NanoTrack v2 + A3BoxNet: one pass", "restart"], rows)
    return table + "\n\n" + models_line(now.values(), '"now"')


def long_table(root: Path) -> str:
    """The long watches (300 frames; long_watch/engine_baseline.json): the loop with the body's
    past views and without them, AO_3d / ACE_3d (m), the default in bold: the views for the range
    sensors (their runs without are named ...-noviews), one view for stereo depth (its runs with
    the views are named ...-views)."""
    now = _runs(root, "long_watch/engine_baseline.json")

    def pair(key):
        r = now.get(key)
        return "-" if r is None else f"{r['ao_3d']:.3f} / {r['ace_3d']:.3f}"

    rows = []
    for s, sp in sorted({(k[0], k[1]) for k in now}, key=lambda x: (ENGINE_SPLITS.index(x), x)):
        if (s, sp, "onepass", "edgetrack+a3boxnet-views") in now:
            # a sensor whose default is one view (stereo): its plain runs are the default, bold
            cells = [f"**{pair((s, sp, 'restart', 'oracle+a3boxnet'))}**",
                     pair((s, sp, "restart", "oracle+a3boxnet-views")),
                     f"**{pair((s, sp, 'onepass', 'edgetrack+a3boxnet'))}**",
                     pair((s, sp, "onepass", "edgetrack+a3boxnet-views"))]
        else:
            cells = [pair((s, sp, "restart", "oracle+a3boxnet-noviews")),
                     f"**{pair((s, sp, 'restart', 'oracle+a3boxnet'))}**",
                     pair((s, sp, "onepass", "edgetrack+a3boxnet-noviews")),
                     f"**{pair((s, sp, 'onepass', 'edgetrack+a3boxnet'))}**"]
        rows.append([s, sp, *cells,
                     pair((s, sp, "onepass", "siamfc-edge+a3boxnet")), pair((s, sp, "onepass", "nano+a3boxnet"))])
    return markdown_table(["depth", "split", "A3BoxNet, oracle 2D: one view", "past views",
                           "Track3D default (EdgeTrack), one pass: one view", "past views",
                           "SiamFC-edge + A3BoxNet, one pass", "NanoTrack v2 + A3BoxNet, one pass"], rows)


def models_line(rows, what: str) -> str:
    """One line naming the model files (sha256 prefixes, from the runs' records) behind `rows`."""
    seen: dict[str, set] = {}
    for r in rows:
        for f, h in (r.get("models") or {}).items():
            seen.setdefault(f, set()).add(h)
    if not seen:
        return f"Models of {what}: not recorded."
    return (f"Models of {what} (sha256 prefix; `sha256sum runtime/track3d/models/*.onnx`): "
            + ", ".join(f"{f} `{'`/`'.join(sorted(h))}`" for f, h in sorted(seen.items())) + ".")


def _table2_metrics(root: Path, source: str, row: str) -> dict:
    if source == "bench_2d":   # the one-pass 2D benchmark: its own keys, no restarts by protocol
        r = _load(root, "siamfc/bench_2d.json")["trackers"][row]
        return {"ao_2d": r["AO_2d"], "ace_2d": r["ACE_2d"], "restarts": 0}
    if source == "edgetrack_2d":   # EdgeTrack's one-pass 2D evaluation (track3d-train edgetrack eval)
        r = _load(root, "edgetrack/engine_eval_test.json")["trackers"][row]
        return {"ao_2d": r["ao_2d"], "ace_2d": r["ace_2d"], "restarts": 0}
    rec = _load(root, f"{source}/table2.json")
    if row.startswith("sweep:"):
        return next(x for x in rec["sweep"] if x["run"] == row[len("sweep:"):])["metrics"]
    return next(x for x in rec["rows"] if x["row"] == row)["metrics"]


def _table2(root: Path, specs) -> str:
    fmts = (("ao_2d", "AO_2d", "{:.3f}"), ("ace_2d", "ACE_2d(px)", "{:.1f}"), ("ao_bev", "AO_bev", "{:.3f}"),
            ("ao_3d", "AO_3d", "{:.3f}"), ("ace_3d", "ACE_3d(m)", "{:.3f}"))
    shown = {"full": {"ao_2d", "ace_2d", "ao_bev", "ao_3d", "ace_3d"}, "oracle": {"ao_bev", "ao_3d", "ace_3d"},
             "2d": {"ao_2d", "ace_2d"}}
    rows = []
    for spec in specs:
        if spec[0] == "paper":
            p = TABLE2[spec[1]]
            rows.append([f"*paper: {PAPER_LABELS[spec[1]]}*"]
                        + [f"*{cell(p[k], f)}*" if p[k] is not None else "-" for _, k, f in fmts] + [""])
            continue
        label, source, row, kind, bold = spec
        m = _table2_metrics(root, source, row)
        cells = [cell(m[k], f) if k in shown[kind] else "-" for k, _, f in fmts]
        if bold:
            cells = [f"**{c}**" for c in cells]
        rows.append([label] + cells + [str(m["restarts"])])
    return markdown_table(["row", "AO_2d", "ACE_2d (px)", "AO_bev", "AO_3d", "ACE_3d (m)", "restarts"], rows)


def table2_table(root: Path) -> str:
    return _table2(root, TABLE2_ROWS)


def table2_engine_table(root: Path) -> str:
    return _table2(root, TABLE2_ENGINE_ROWS)


def first_box_table(root: Path) -> str:
    """Track3D (EdgeTrack, one pass) started from the 2D box alone and from the first 3D box
    (`track3d track --init-3d`; first_box/engine_baseline.json), AO_3d / ACE_3d (m)."""
    now = {(r["sensor"], r["split"], r["tracker"]): r for r in _load(root, "first_box/engine_baseline.json")["rows"]}

    def pair(key):
        r = now.get(key)
        return "-" if r is None else f"{r['ao_3d']:.3f} / {r['ace_3d']:.3f}"

    rows = [[s, sp, pair((s, sp, "edgetrack+a3boxnet")), f"**{pair((s, sp, 'edgetrack+a3boxnet-init3d'))}**",
             pair((s, sp, "nano+a3boxnet")), pair((s, sp, "nano+a3boxnet-init3d"))]
            for s, sp in ENGINE_SPLITS if (s, sp, "edgetrack+a3boxnet") in now]
    return markdown_table(["depth", "split", "Track3D default, one pass: 2D start", "with the first 3D box",
                           "NanoTrack v2 + A3BoxNet, one pass: 2D start", "with the first 3D box"], rows)


# The aims (issue 12's targets and the 150 FPS of one core), each judged on the 60-frame sets
# (engine_current: 6 s a sequence) and on the long watches (long_watch: 30 s), the default loop's
# one pass (what a spacecraft gets) and A3BoxNet with oracle 2D boxes. (label, kind, sensor, split,
# tracker, AO_3d at least, ACE_3d at most); kind "gap": the held-out split's AO_3d within `ao` of
# the test split's.
AIMS = (
    ("A3BoxNet, oracle 2D, ideal depth, test: AO_3d >= 0.85, ACE_3d <= 0.25 m", "abs", "ideal", "test",
     "oracle", 0.85, 0.25),
    ("A3BoxNet, oracle 2D, ideal depth, held-out shapes: AO_3d >= 0.80, ACE_3d <= 0.30 m", "abs", "ideal",
     "test_unseen", "oracle", 0.80, 0.30),
    ("Track3D default, one pass, ideal depth, test: AO_3d >= 0.85, ACE_3d <= 0.25 m", "abs", "ideal", "test",
     "edgetrack", 0.85, 0.25),
    ("Track3D default, one pass, ideal depth, held-out shapes: AO_3d within 0.03 of the test split", "gap",
     "ideal", "test_unseen", "edgetrack", 0.03, None),
) + tuple((f"Track3D default, one pass, {s} depth, {name}: AO_3d >= 0.75", "abs", s, sp, "edgetrack", 0.75, None)
          for s in ("flash-lidar", "tof", "stereo") for sp, name in (("test", "test"), ("test_unseen", "held-out shapes")))
_AIM_RUNS = {"oracle": ("restart", "oracle+a3boxnet"), "edgetrack": ("onepass", "edgetrack+a3boxnet")}


def _interval(row: dict, key: str, fmt: str) -> str:
    """' (lo-hi)': the row's bootstrap interval of `key` over sequences, '' for a row without one."""
    iv = (row.get("intervals") or {}).get(key)
    if not iv or any(v is None or not np.isfinite(v) for v in iv):
        return ""
    return f" ({fmt.format(iv[0])}-{fmt.format(iv[1])})"


def _aim_cell(rows: dict, kind: str, sensor: str, split: str, tracker: str, ao: float, ace) -> str:
    protocol, name = _AIM_RUNS[tracker]
    r = rows.get((sensor, split, protocol, name))
    if r is None:
        return "-"
    if kind == "gap":
        t = rows.get((sensor, "test", protocol, name))
        if t is None:
            return "-"
        d = r["ao_3d"] - t["ao_3d"]
        return f"{r['ao_3d']:.3f} vs {t['ao_3d']:.3f} ({d:+.3f}): {'met' if d >= -ao else '**not met**'}"
    met = r["ao_3d"] >= ao and (ace is None or r["ace_3d"] <= ace)
    text = f"{r['ao_3d']:.3f}" + _interval(r, "ao_3d", "{:.3f}") + (
        f" / {r['ace_3d']:.3f}" + _interval(r, "ace_3d", "{:.2f}") + " m" if ace is not None else "")
    return f"{text}: {'met' if met else '**not met**'}"


def _peer_cell(rows: dict, protocol: str, peers: tuple[str, ...] = ("nano+a3boxnet",)) -> str:
    """EdgeTrack's loop against each peer's in the same loop (NanoTrack v2 by default), AO_3d per
    (sensor, split, peer): how many ahead, level (within 0.0005: the same at the table's 3
    decimals) and behind; when every pair was compared sequence by sequence (the peer's row
    "paired" against EdgeTrack's, from one report), how many of the leads and of the losses lie
    beyond the paired 95% interval."""
    pairs = [(rows[(s, sp, protocol, "edgetrack+a3boxnet")], rows[(s, sp, protocol, peer)])
             for s, sp in ENGINE_SPLITS for peer in peers
             if (s, sp, protocol, "edgetrack+a3boxnet") in rows and (s, sp, protocol, peer) in rows]
    if not pairs:
        return "-"
    d = [e["ao_3d"] - n["ao_3d"] for e, n in pairs]
    ahead, behind = sum(x >= 0.0005 for x in d), sum(x <= -0.0005 for x in d)
    # NanoTrack - EdgeTrack per sequence: EdgeTrack surely ahead when the interval lies below 0
    iv = [(n.get("paired") or {}) for _, n in pairs]
    sure = all(p.get("baseline") == "edgetrack+a3boxnet" and "ao_3d" in p for p in iv)
    sure_ahead = sum(x >= 0.0005 and p["ao_3d"]["hi"] < 0 for x, p in zip(d, iv)) if sure else 0
    sure_behind = sum(x <= -0.0005 and p["ao_3d"]["lo"] > 0 for x, p in zip(d, iv)) if sure else 0
    def n(k: int, s: int) -> str:
        return f"{k} ({s} beyond the paired 95% interval)" if sure and k else str(k)
    return (f"ahead on {n(ahead, sure_ahead)}, level on {len(d) - ahead - behind}, behind on "
            f"{n(behind, sure_behind)} of {len(d)}: {'met' if behind == 0 else '**not met**'}")


# OpenCV's trackers inside the same loop on the engine's 60-frame sets (engine_baseline.py of
# `track3d track --tracker T` runs beside EdgeTrack's, one report per sensor, split and protocol)
OPENCV_PEERS = "opencv_peers/engine_baseline.json"
OPENCV_TRACKERS = ("kcf", "csrt", "mosse", "mil")
OPENCV_NAMES = ("KCF", "CSRT", "MOSSE", "MIL")


# the 2D trackers alone on the engine's images, one pass (`track3d-train edgetrack eval --compare`)
PEERS_2D = "edgetrack/engine_eval_{split}_peers.json"
# ... and on each long watch's images (each depth sensor's long watch is its own scenes)
PEERS_2D_LONG = "edgetrack/long_eval_{sensor}_{split}_peers.json"
# the long watches' runs, the peers' among them: EdgeTrack and NanoTrack v2 with restarts too,
# OpenCV's trackers both ways, each report paired against EdgeTrack's row of its protocol
LONG_PEERS = "long_watch/engine_baseline.json"


def _cell_2d(root: Path, files: tuple[str, ...] = tuple(PEERS_2D.format(split=s) for s in ("test", "test_unseen"))
             ) -> str:
    """EdgeTrack's AO_2d alone against every other tracker of the same run, per split (one file
    each): on how many splits it is ahead of each (by 0.0005 or more), with its AO_2d and the best
    other's."""
    got = []
    for rel in files:
        f = root / RESULTS / rel
        if f.exists():
            t = json.loads(f.read_text())["trackers"]
            ours = t.pop("edgetrack", None) or t.pop("model edgetrack", None)
            if ours is not None and t:
                got.append((ours["ao_2d"], max(v["ao_2d"] for v in t.values()), len(t)))
    if not got:
        return "-"
    ahead = sum(e - b >= 0.0005 for e, b, _ in got)
    vals = " / ".join(f"{e:.3f}" for e, _, _ in got) + " vs the best other " + " / ".join(f"{b:.3f}" for _, b, _ in got)
    return (f"ahead of all {got[0][2]} on {ahead} of {len(got)} splits (AO_2d {vals}): "
            f"{'met' if ahead == len(got) else '**not met**'}")


def peers_table(root: Path) -> str:
    """AO_3d of the loop under each 2D tracker, one pass, per sensor and split: EdgeTrack (the
    default) and NanoTrack v2 from the engine table's run, OpenCV's trackers from theirs (the
    same sequences; EdgeTrack's row of that run, the same loop, is the one they are paired with)."""
    now, opencv = _runs(root, "engine_current/engine_baseline.json"), _runs(root, OPENCV_PEERS, optional=True)

    def ao(by, key, bold=False):
        r = by.get(key)
        return "-" if r is None else (f"**{r['ao_3d']:.3f}**" if bold else f"{r['ao_3d']:.3f}")

    rows = []
    for s, sp in ENGINE_SPLITS:
        rows.append([s, sp, ao(now, (s, sp, "onepass", "edgetrack+a3boxnet"), True),
                     ao(now, (s, sp, "onepass", "nano+a3boxnet"))]
                    + [ao(opencv, (s, sp, "onepass", f"{t}+a3boxnet")) for t in OPENCV_TRACKERS])
    return markdown_table(["sensor", "split", "EdgeTrack (default)", "NanoTrack v2"] + list(OPENCV_NAMES), rows)


def long_peers_table(root: Path) -> str:
    """AO_3d of the loop under each 2D tracker over the long watches (300 frames), one pass and
    with the paper's restarts (the restarts made in brackets)."""
    long_, peers = _runs(root, "long_watch/engine_baseline.json"), _runs(root, LONG_PEERS, optional=True)

    def ao(by, key, bold=False, restarts=False):
        r = by.get(key)
        if r is None:
            return "-"
        text = f"{r['ao_3d']:.3f}" + (f" ({r['restarts']})" if restarts and r.get("restarts") is not None else "")
        return f"**{text}**" if bold else text

    rows = []
    for s, sp in ENGINE_SPLITS:
        rows.append([s, sp, ao(long_, (s, sp, "onepass", "edgetrack+a3boxnet"), True),
                     ao(long_, (s, sp, "onepass", "nano+a3boxnet"))]
                    + [ao(peers, (s, sp, "onepass", f"{t}+a3boxnet")) for t in OPENCV_TRACKERS]
                    + [ao(peers, (s, sp, "restart", "edgetrack+a3boxnet"), True, True),
                       ao(peers, (s, sp, "restart", "nano+a3boxnet"), restarts=True)]
                    + [ao(peers, (s, sp, "restart", f"{t}+a3boxnet"), restarts=True) for t in OPENCV_TRACKERS])
    one = ["EdgeTrack", "NanoTrack v2"] + list(OPENCV_NAMES)
    return markdown_table(["sensor", "split"] + [f"{n}, one pass" for n in one]
                          + [f"{n}, restarts" for n in one], rows)


def aims_table(root: Path) -> str:
    """Where the shipped loop stands against its aims, from the committed result JSON: every
    accuracy aim on the 60-frame sets and on the long watches, and the speed aim (>= 150 FPS on
    one core) from the speed table's run."""
    short, long_ = _runs(root, "engine_current/engine_baseline.json"), _runs(root, "long_watch/engine_baseline.json")
    rows = [[label, _aim_cell(short, *spec), _aim_cell(long_, *spec)] for label, *spec in AIMS]
    long_peers = _runs(root, LONG_PEERS, optional=True)
    rows += [[f"Track3D default vs NanoTrack v2 + A3BoxNet (peer), {name}: at or ahead on every sensor and split",
              _peer_cell(short, protocol), _peer_cell(long_ if protocol == "onepass" else long_peers, protocol)]
             for protocol, name in (("onepass", "one pass"), ("restart", "with restarts"))]
    opencv = _runs(root, OPENCV_PEERS, optional=True)
    cv = tuple(f"{t}+a3boxnet" for t in OPENCV_TRACKERS)
    rows += [[f"Track3D default vs OpenCV's {', '.join(OPENCV_NAMES)} + A3BoxNet, {name}: at or ahead of each on "
              "every sensor and split", _peer_cell(opencv, protocol, cv), _peer_cell(long_peers, protocol, cv)]
             for protocol, name in (("onepass", "one pass"), ("restart", "with restarts"))]
    long_2d = tuple(PEERS_2D_LONG.format(sensor=s, split=sp) for s, sp in ENGINE_SPLITS)
    rows.append([f"EdgeTrack vs NanoTrack v2 and OpenCV's {', '.join(OPENCV_NAMES)} in 2D alone, one pass: ahead of "
                 "each on every split", _cell_2d(root), _cell_2d(root, long_2d)])
    label, rel, config, _ = SPEED_ROWS[0]
    r = next(x for x in _load(root, rel)["results"] if x["config"] == config and x["backend"] == "onnxruntime"
             and x["precision"] == "fp32")
    fps = r["fps_median"]   # shown rounded down: 149.6 must not read as 150 and "not met"
    rows.append([f"{label}: >= 150 FPS on one core", f"{int(fps)} FPS: {'met' if fps >= 150 else '**not met**'}",
                 "-"])
    return markdown_table(["aim", "60-frame sets (6 s)", "long watches (300 frames, 30 s)"], rows)


TABLES = {"speed": speed_table, "engine": engine_table, "long": long_table, "table2": table2_table,
          "table2_engine": table2_engine_table, "first_box": first_box_table, "aims": aims_table,
          "peers": peers_table, "long_peers": long_peers_table}


def render(readme: str, root: Path) -> str:
    """README text with every marked section replaced by its generated table."""
    def section(m: re.Match) -> str:
        return f"{m.group(1)}\n{TABLES[m.group(2)](root)}\n{m.group(3)}"

    # the lines between a marker pair, none of them a marker: an empty section must not reach
    # over to the next section's end marker (it once swallowed a whole table)
    return re.sub(r"(<!-- readme_tables\.py: (\w+) -->)\n(?:(?!<!-- /?readme_tables\.py)[^\n]*\n)*"
                  r"(<!-- /readme_tables\.py -->)", section, readme)


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--readme", type=Path, default=REPO / "README.md", help="the README (default: the repository's)")
    ap.add_argument("--root", type=Path, default=REPO, help="the repository holding benchmarks/results")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--check", action="store_true", help="exit 1 when the README's tables differ from the JSON")
    mode.add_argument("--write", action="store_true", help="update the README's marked sections in place")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    if not (a.check or a.write):
        for name, fn in TABLES.items():
            print(f"<!-- readme_tables.py: {name} -->\n{fn(a.root)}\n")
        return 0
    text = a.readme.read_text()
    new = render(text, a.root)
    if a.write:
        a.readme.write_text(new)
        print(f"updated {a.readme}" if new != text else f"{a.readme} was up to date")
        return 0
    if new != text:
        print(f"{a.readme}: the result tables differ from benchmarks/results (run benchmarks/readme_tables.py --write)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main, "readme_tables.py"))
