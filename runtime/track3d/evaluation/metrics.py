"""Tracking metrics of the paper (section III-C), per sequence and over sequences.

Per sequence, over its *scored* frames (the target is present and the frame is not an
initialisation frame, whose result is the ground truth itself):

- AO (2D, BEV, 3D): mean IoU; SR@0.5 / SR@0.75: fraction of frames with IoU > threshold
  (strictly greater, as the GOT-10k toolkit);
- ACE_2d (pixels) / ACE_3d (metres): mean centre distance over the scored frames that have a
  prediction (frames skipped after a restart have none: IoU 0, no centre error);
- success curve: SR at IoU thresholds 0..1; precision curve: fraction of scored frames with
  centre error <= threshold (a frame without prediction counts as a miss).

Over sequences: the mean of the per-sequence values (paper eq. for AO^3d and ACE^3d: every
sequence weighs the same), curves averaged likewise; restarts are summed; FPS is frames over
time summed over all sequences. IoU and centre error come from track3d.boxes (one formula).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..boxes import center_error_2d, center_error_3d, iou_2d, iou_3d, iou_bev

__all__ = [
    "IOU_THRESHOLDS", "CE2D_THRESHOLDS", "CE3D_THRESHOLDS", "success_curve", "precision_curve",
    "SequenceScore", "OverallScore", "score_sequence", "average_scores", "KINDS",
]

IOU_THRESHOLDS = np.linspace(0.0, 1.0, 101)
CE2D_THRESHOLDS = np.linspace(0.0, 50.0, 51)     # pixels, as OTB's precision plot
CE3D_THRESHOLDS = np.linspace(0.0, 4.0, 81)      # metres, 5 cm steps
KINDS = ("2d", "bev", "3d")


def success_curve(ious: np.ndarray, thresholds: np.ndarray = IOU_THRESHOLDS) -> np.ndarray:
    """Fraction of frames with IoU > t for each threshold t; (T,) float64, zeros when no frame."""
    v = np.asarray(ious, dtype=np.float64).reshape(-1)
    if len(v) == 0:
        return np.zeros(len(thresholds))
    return (v[:, None] > np.asarray(thresholds)[None, :]).mean(axis=0)


def precision_curve(errors: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """Fraction of frames with centre error <= t; nan errors (no prediction) never count."""
    e = np.asarray(errors, dtype=np.float64).reshape(-1)
    if len(e) == 0:
        return np.zeros(len(thresholds))
    e = np.where(np.isnan(e), np.inf, e)
    return (e[:, None] <= np.asarray(thresholds)[None, :]).mean(axis=0)


def _mean_or_nan(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


@dataclass
class SequenceScore:
    """Scores of one sequence (see module docstring); curves are (T,) arrays."""

    name: str
    frames: int                     # scored frames
    restarts: int
    ao_2d: float
    sr50_2d: float
    sr75_2d: float
    ace_2d: float
    ao_bev: float
    sr50_bev: float
    sr75_bev: float
    ao_3d: float
    sr50_3d: float
    sr75_3d: float
    ace_3d: float
    tracker_seconds: float = 0.0    # tracker time of the timed frames (I/O excluded)
    e2e_seconds: float = 0.0        # the same frames end to end (image + depth reading included)
    timed_frames: int = 0
    curves: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def fps(self) -> float:
        return self.timed_frames / self.tracker_seconds if self.tracker_seconds > 0 else float("nan")

    @property
    def fps_e2e(self) -> float:
        return self.timed_frames / self.e2e_seconds if self.e2e_seconds > 0 else float("nan")

    def summary(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "curves"}
        d["fps"], d["fps_e2e"] = self.fps, self.fps_e2e
        return d


def score_sequence(name: str, pred2d: np.ndarray, pred3d: np.ndarray, gt2d: np.ndarray, gt3d: np.ndarray,
                   scored: np.ndarray, restarts: int = 0, tracker_seconds: float = 0.0,
                   e2e_seconds: float = 0.0, timed_frames: int = 0) -> SequenceScore:
    """Score one sequence. pred2d/gt2d (T, 4), pred3d/gt3d (T, 6); scored (T,) bool marks the
    frames that count (present target, not an init frame). Predictions may be nan (no output)."""
    pred2d = np.asarray(pred2d, np.float64).reshape(-1, 4)
    pred3d = np.asarray(pred3d, np.float64).reshape(-1, 6)
    gt2d = np.asarray(gt2d, np.float64).reshape(-1, 4)
    gt3d = np.asarray(gt3d, np.float64).reshape(-1, 6)
    scored = np.asarray(scored, bool).reshape(-1)
    n = len(scored)
    if not (len(pred2d) == len(pred3d) == len(gt2d) == len(gt3d) == n):
        raise ValueError(f"sequence {name}: predictions, ground truth and flags differ in length "
                         f"({len(pred2d)}, {len(pred3d)}, {len(gt2d)}, {len(gt3d)}, {n})")
    p2, p3, g2, g3 = pred2d[scored], pred3d[scored], gt2d[scored], gt3d[scored]
    ious = {"2d": iou_2d(p2, g2), "bev": iou_bev(p3, g3), "3d": iou_3d(p3, g3)}
    with np.errstate(invalid="ignore"):
        ce2 = center_error_2d(p2, g2)
        ce3 = center_error_3d(p3, g3)
    curves = {f"success_{k}": success_curve(v) for k, v in ious.items()}
    curves["precision_2d"] = precision_curve(ce2, CE2D_THRESHOLDS)
    curves["precision_3d"] = precision_curve(ce3, CE3D_THRESHOLDS)

    def ao(k):
        return float(ious[k].mean()) if len(p2) else float("nan")

    def sr(k, t):
        return float((ious[k] > t).mean()) if len(p2) else float("nan")

    return SequenceScore(
        name=name, frames=int(scored.sum()), restarts=int(restarts),
        ao_2d=ao("2d"), sr50_2d=sr("2d", 0.5), sr75_2d=sr("2d", 0.75), ace_2d=_mean_or_nan(ce2),
        ao_bev=ao("bev"), sr50_bev=sr("bev", 0.5), sr75_bev=sr("bev", 0.75),
        ao_3d=ao("3d"), sr50_3d=sr("3d", 0.5), sr75_3d=sr("3d", 0.75), ace_3d=_mean_or_nan(ce3),
        tracker_seconds=float(tracker_seconds), e2e_seconds=float(e2e_seconds),
        timed_frames=int(timed_frames), curves=curves)


SCALARS = ("ao_2d", "sr50_2d", "sr75_2d", "ace_2d", "ao_bev", "sr50_bev", "sr75_bev",
           "ao_3d", "sr50_3d", "sr75_3d", "ace_3d")


@dataclass
class OverallScore:
    """Averages over sequences (each sequence weighs the same); see module docstring."""

    sequences: int
    frames: int
    restarts: int
    values: dict[str, float]
    fps: float
    fps_e2e: float
    curves: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def summary(self) -> dict:
        return {"sequences": self.sequences, "frames": self.frames, "restarts": self.restarts,
                **self.values, "fps": self.fps, "fps_e2e": self.fps_e2e}


def average_scores(scores: list[SequenceScore]) -> OverallScore:
    """Mean over the sequences that have scored frames; restarts and times are summed."""
    used = [s for s in scores if s.frames > 0]
    values = {}
    for k in SCALARS:
        v = np.array([getattr(s, k) for s in used], dtype=np.float64)
        values[k] = _mean_or_nan(v)
    curves = {}
    if used:
        for k in used[0].curves:
            curves[k] = np.mean([s.curves[k] for s in used], axis=0)
    t = sum(s.tracker_seconds for s in scores)
    e = sum(s.e2e_seconds for s in scores)
    n = sum(s.timed_frames for s in scores)
    return OverallScore(sequences=len(used), frames=sum(s.frames for s in scores),
                        restarts=sum(s.restarts for s in scores), values=values,
                        fps=n / t if t > 0 else float("nan"), fps_e2e=n / e if e > 0 else float("nan"),
                        curves=curves)
