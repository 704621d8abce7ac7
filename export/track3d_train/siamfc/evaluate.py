"""One-pass evaluation (OPE) of 2D trackers on a dataset split (paper §III-C, 2D metrics).

Init on the first frame where the target is present, update on every later frame, no restart
(the 2D protocol of the paper's Fig. 14). Frames where the target is absent do not count. When a tracker reports failure (ok False) its
last box is held for that frame (counted in "lost").
Metric formulas come from track3d.boxes (iou_2d, center_error_2d); AO_2d, SR@0.5 and ACE_2d
are averaged per sequence, then over sequences.
"""
from __future__ import annotations

import time

import numpy as np

from track3d.boxes import center_error_2d, iou_2d

__all__ = ["run_sequence", "summarise", "IOU_THRESHOLDS", "CE_THRESHOLDS", "load_frames"]

IOU_THRESHOLDS = np.linspace(0, 1, 21)
CE_THRESHOLDS = np.arange(0, 51)


def load_frames(seq) -> np.ndarray:
    return np.stack([seq.image(i) for i in range(len(seq))])


def run_sequence(tracker, frames: np.ndarray, gt: np.ndarray, absent: np.ndarray | None = None) -> dict:
    """Track one sequence; returns per-frame IoU/centre error on counted frames and timing."""
    n = len(gt)
    absent = np.zeros(n, bool) if absent is None else np.asarray(absent, bool)
    valid = (~absent) & np.all(np.isfinite(gt), axis=1) & (gt[:, 2] > 0) & (gt[:, 3] > 0)
    first = int(np.argmax(valid)) if valid.any() else None
    if first is None:
        return {"iou": np.zeros(0), "ce": np.zeros(0), "update_s": [], "frames": 0}
    tracker.init(frames[first], gt[first].copy())
    pred = np.full((n, 4), np.nan)
    pred[first] = gt[first]
    times = []
    lost = 0
    for i in range(first + 1, n):
        t0 = time.perf_counter()
        ok, box = tracker.update(frames[i])
        times.append(time.perf_counter() - t0)
        b = np.asarray(box, np.float64).reshape(-1)
        good = ok and b.shape == (4,) and np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0
        pred[i] = b if good else pred[i - 1]  # a reported failure holds the last box
        lost += not good
    idx = np.nonzero(valid)[0]
    idx = idx[idx > first]
    p = pred[idx]
    iou = iou_2d(p, gt[idx])
    ce = center_error_2d(p, gt[idx])
    return {"iou": iou, "ce": ce, "update_s": times, "frames": len(times), "pred": pred, "lost": lost}


def summarise(results: list[dict]) -> dict:
    """Average per sequence, then over sequences."""
    rs = [r for r in results if len(r["iou"])]
    if not rs:
        return {"sequences": 0}
    ao = np.mean([r["iou"].mean() for r in rs])
    sr50 = np.mean([(r["iou"] > 0.5).mean() for r in rs])
    sr75 = np.mean([(r["iou"] > 0.75).mean() for r in rs])
    ace = np.mean([r["ce"].mean() for r in rs])
    succ = np.mean([[(r["iou"] > t).mean() for t in IOU_THRESHOLDS] for r in rs], axis=0)
    prec = np.mean([[(r["ce"] <= t).mean() for t in CE_THRESHOLDS] for r in rs], axis=0)
    t = np.concatenate([np.asarray(r["update_s"]) for r in rs])
    return {"sequences": len(rs), "frames": int(sum(len(r["iou"]) for r in rs)),
            "AO_2d": float(ao), "SR_0.5": float(sr50), "SR_0.75": float(sr75), "ACE_2d": float(ace),
            "success_curve": succ.tolist(), "precision_curve": prec.tolist(),
            "update_ms_mean": float(1e3 * t.mean()), "update_ms_median": float(1e3 * np.median(t)),
            "fps": float(1.0 / t.mean())}
