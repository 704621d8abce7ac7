"""The Table-2-style text table of an evaluation report (`track3d eval`, the demo)."""
from __future__ import annotations

from ..table_text import cell
from .metrics import AXES_3D, CONDITIONS

__all__ = ["TABLE_COLUMNS", "columns", "summary_table", "tracker_2d_table", "axis_table", "paired_table", "condition_table",
           "sequence_table"]

TABLE_COLUMNS = (("AO_2d", "ao_2d", "{:.3f}"), ("ACE_2d(px)", "ace_2d", "{:.2f}"), ("AO_bev", "ao_bev", "{:.3f}"),
                 ("AO_3d", "ao_3d", "{:.3f}"), ("ACE_3d(m)", "ace_3d", "{:.3f}"), ("SR50_3d", "sr50_3d", "{:.3f}"),
                 ("lost_P", "lost_precision", "{:.2f}"), ("lost_R", "lost_recall", "{:.2f}"),
                 ("restarts", "restarts", "{:d}"), ("frames", "frames", "{:d}"), ("FPS", "fps", "{:.1f}"),
                 ("FPS_e2e", "fps_e2e", "{:.1f}"), ("p99_ms", "ms_p99", "{:.1f}"))


def columns(*keys: str) -> tuple[tuple[str, str, str], ...]:
    """The TABLE_COLUMNS entries of these score keys, in this order (a table of fewer columns)."""
    by_key = {c[1]: c for c in TABLE_COLUMNS}
    return tuple(by_key[k] for k in keys)


def summary_table(report: dict) -> str:
    """A Table-2-style text table of a report's overall scores (one row per tracker)."""
    rows = [["name"] + [c[0] for c in TABLE_COLUMNS]]
    for name, t in report["trackers"].items():
        ov = t["overall"]
        row = [name]
        for _, key, fmt in TABLE_COLUMNS:
            row.append(cell(ov.get(key), fmt))
        rows.append(row)
    return _aligned(rows)


def tracker_2d_table(rows: dict[str, dict]) -> str:
    """The 2D trackers' one-pass scores (`evaluate_2d`'s rows: name -> overall scores) as the
    summary table's 2D columns, one line a tracker."""
    cols = columns("ao_2d", "ace_2d", "lost_precision", "lost_recall", "frames", "fps") + (
        ("SR50_2d", "sr50_2d", "{:.3f}"), ("SR75_2d", "sr75_2d", "{:.3f}"), ("ms_median", "ms_median", "{:.2f}"))
    table = [["name"] + [c[0] for c in cols]]
    for name, r in rows.items():
        table.append([name] + [cell(r.get(key), fmt) for _, key, fmt in cols])
    return _aligned(table)


def axis_table(report: dict) -> str:
    """Where each tracker's 3D error lies: per box coordinate (AXES_3D, the camera frame, z along the
    line of sight) the mean over sequences of the bias (prediction - truth) and of the mean |error|,
    in metres; "" when no tracker of the report has 3D boxes."""
    rows = [["3D error (m)"] + [f"bias {a}" for a in AXES_3D] + [f"|e| {a}" for a in AXES_3D]]
    for name, t in report["trackers"].items():
        ov = t["overall"]
        if "bias_3d" not in ov:   # 2D only
            continue
        rows.append([name] + [cell(v, "{:+.3f}") for v in ov["bias_3d"]] + [cell(v, "{:.3f}") for v in ov["mae_3d"]])
    return _aligned(rows) if len(rows) > 1 else ""


def paired_table(report: dict) -> str:
    """How sure the means are: AO_3d (AO_2d when no run has 3D boxes) over sequences with its
    bootstrap interval per run, and each run against the report's baseline sequence by sequence
    (the mean difference, its interval, the sequences better / worse by more than the margin);
    "" for a report without intervals (one written before them)."""
    trackers, paired = report["trackers"], report.get("paired")
    if not trackers or paired is None or any("intervals" not in t for t in trackers.values()):
        return ""
    has_3d = any("bias_3d" in t["overall"] for t in trackers.values())
    key, label = ("ao_3d", "AO_3d") if has_3d else ("ao_2d", "AO_2d")
    pct = f"{round(100 * paired['level'])}%"
    rows = [["name", label, f"{pct} interval", f"d{label} vs {paired['baseline']}", f"{pct} interval", "better",
             "worse"]]
    for name, t in trackers.items():
        lo, hi = t["intervals"][key]
        row = [name, cell(t["overall"].get(key), "{:.3f}"), f"{cell(lo, '{:.3f}')} .. {cell(hi, '{:.3f}')}"]
        p = paired["trackers"].get(name, {}).get(key)
        if p is None:
            row += ["-", "-", "-", "-"]
        else:
            row += [cell(p["mean"], "{:+.4f}"), f"{cell(p['lo'], '{:+.4f}')} .. {cell(p['hi'], '{:+.4f}')}",
                    str(p["better"]), str(p["worse"])]
        rows.append(row)
    n = max(t["overall"].get("sequences", 0) for t in trackers.values())
    head = (f"over {n} sequences, bootstrap intervals; better / worse: sequences whose {label} moved by more "
            f"than {paired['margin']:g}")
    return head + "\n" + _aligned(rows)


def condition_table(report: dict) -> str:
    """Where the loss is: per tracker, the scored frames pooled by their condition (metrics.CONDITIONS;
    the conditions no tracker has a frame in left out) with their share of the frames, AO_2d,
    AO_3d, ACE_3d and the AO_3d lost there (the shares of (1 - IoU_3d) over all frames); "" for
    a report without conditions (one written before them) or with every frame "whole"."""
    trackers = report["trackers"]
    if not trackers or any("conditions" not in t for t in trackers.values()):
        return ""
    used = [k for k in CONDITIONS if any(t["conditions"].get(k, {}).get("frames", 0) for t in trackers.values())]
    if used in ([], ["whole"]):
        return ""
    rows = [["frames by condition", "condition", "frames", "share", "AO_2d", "AO_3d", "ACE_3d(m)", "AO_3d lost"]]
    for name, t in trackers.items():
        for k in used:
            c = t["conditions"][k]
            rows.append([name, k, str(c["frames"]), cell(c["share"], "{:.2f}"), cell(c["ao_2d"], "{:.3f}"),
                         cell(c.get("ao_3d"), "{:.3f}"), cell(c.get("ace_3d"), "{:.3f}"),
                         cell(c.get("ao_3d_lost"), "{:.3f}")])
    return _aligned(rows)


def sequence_table(report: dict) -> str:
    """Each sequence's scores, the runs side by side (a row per sequence and run, in the report's
    sequence order): frames, AO_2d, AO_3d, ACE_3d, the bias of the centre depth and of the depth
    extent (cz, sz: the line of sight, where the hidden depth shows) and AO_3d (AO_2d when no run
    has 3D boxes) against the report's baseline run on the same sequence; "" for a report without
    runs. The per-sequence numbers behind the summary's means (`track3d eval --per-sequence`,
    sequences.txt in the report folder)."""
    trackers = report["trackers"]
    if not trackers:
        return ""
    has_3d = any("bias_3d" in t["overall"] for t in trackers.values())
    key, label = ("ao_3d", "AO_3d") if has_3d else ("ao_2d", "AO_2d")
    base = (report.get("paired") or {}).get("baseline")
    iz, isz = AXES_3D.index("cz"), AXES_3D.index("sz")
    rows = [["sequence", "run", "frames", "AO_2d", "AO_3d", "ACE_3d(m)", "bias cz(m)", "bias sz(m)",
             f"d{label} vs {base}" if base else f"d{label}"]]
    order = list(report.get("sequences") or [])
    for t in trackers.values():   # a sequence some run has and the report's list lacks goes last
        order += [s for s in t["sequences"] if s not in order]
    for seq in order:
        ref = trackers.get(base, {}).get("sequences", {}).get(seq) if base else None
        for name, t in trackers.items():
            s = t["sequences"].get(seq)
            if s is None:
                continue
            bias = s.get("bias_3d")
            d = (None if ref is None or name == base or s.get(key) is None or ref.get(key) is None
                 else s[key] - ref[key])
            rows.append([seq, name, str(s.get("frames", 0)), cell(s.get("ao_2d"), "{:.3f}"),
                         cell(s.get("ao_3d"), "{:.3f}"), cell(s.get("ace_3d"), "{:.3f}"),
                         cell(None if bias is None else bias[iz], "{:+.3f}"),
                         cell(None if bias is None else bias[isz], "{:+.3f}"),
                         "-" if name == base else cell(d, "{:+.4f}")])
    return _aligned(rows) if len(rows) > 1 else ""


def _aligned(rows: list[list[str]]) -> str:
    """Text rows of cells: the first column left-aligned, the others right-aligned, two spaces apart."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
                     for r in rows)
