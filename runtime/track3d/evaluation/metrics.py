"""Tracking metrics of the paper (section III-C), per sequence and over sequences.

Per sequence, over its *scored* frames (the target is present and the frame is not an
initialisation frame, whose result is the ground truth itself):

- AO (2D, BEV, 3D): mean IoU; SR@0.5 / SR@0.75: fraction of frames with IoU > threshold
  (strictly greater, as the GOT-10k toolkit);
- ACE_2d (pixels) / ACE_3d (metres): mean centre distance over the scored frames that have a
  prediction (frames skipped after a restart have none: IoU 0, no centre error); over sequences
  it is undefined (nan) when a sequence has no prediction on any scored frame;
- success curve: SR at IoU thresholds 0..1; precision curve: fraction of scored frames with
  centre error <= threshold (a frame without prediction counts as a miss).

2D only (a run of the null estimator "none", or any run without 3D boxes): pred3d None, the
3D scores are nan and there are no 3D curves; every protocol (restarts or one pass, 2D or 3D)
uses these functions and these threshold grids.

Lost detection (one-pass runs of a tracker that reports "lost"): precision and recall of the
frames it calls lost against the frames where the target is absent, and re-acquisition: the
share of the target's returns into view after which the tracker, within `reacquire_frames`
frames, reports a box (not lost) with IoU > REACQUIRE_IOU (:func:`score_lost`).

Where the 3D error lies (bias_3d, mae_3d): per box coordinate [cx, cy, cz, sx, sy, sz] (the
camera frame: z along the line of sight), the mean and the mean absolute of prediction minus
ground truth over the scored frames that have a prediction (:func:`axis_errors_3d`). A box
estimator that guesses the hidden depth of a body shows it in cz and sz.

Where the loss is (:func:`score_conditions`): the scored frames of every sequence pooled by the
condition the ground truth puts them in (CONDITIONS: the body whole in view and within the depth
sensor's range, past the range, cut by the image border, both), each condition's AO_2d, AO_3d and
ACE_3d over its frames and the share of the pooled AO_3d lost there.

Over sequences: the mean of the per-sequence values (paper eq. for AO^3d and ACE^3d: every
sequence weighs the same), curves averaged likewise; restarts are summed; FPS is frames over
time summed over all sequences. IoU and centre error come from track3d.boxes (one formula).
Latency (:func:`latency_ms`): the median, p99 and slowest of the tracker's time per update over
every timed frame of every sequence (FPS is a mean and hides the slow frames a flight computer's
frame budget must hold).

How sure a mean over a few sequences is (:func:`bootstrap_interval`): the percentile bootstrap
interval of the mean over sequences (resampling whole sequences, CI_LEVEL, a fixed seed: the
same numbers on every run). Two runs on the same sequences (:func:`compare_paired`): the mean of
their per-sequence differences with its bootstrap interval, and how many sequences moved by more
than MOVED either way, better or worse by the metric's sense (LOWER_IS_BETTER). Nine or twelve
sequences are few: on the data engine's sets an AO_3d interval spans +-0.02 to +-0.05, so a change
of a mean by 0.005 is a claim only where the paired interval says so.
"""
from __future__ import annotations

from dataclasses import asdict, astuple, dataclass, field

import numpy as np

from ..boxes import center_error_2d, center_error_3d, clip_box2d, iou_2d, iou_3d, iou_bev

__all__ = [
    "IOU_THRESHOLDS", "CE2D_THRESHOLDS", "CE3D_THRESHOLDS", "success_curve", "precision_curve",
    "SequenceScore", "OverallScore", "score_sequence", "average_scores", "KINDS", "SCALARS", "SCALARS_2D",
    "LostScore", "score_lost", "REACQUIRE_IOU", "AXES_3D", "axis_errors_3d",
    "CI_LEVEL", "BOOTSTRAP_RESAMPLES", "MOVED", "LOWER_IS_BETTER", "INTERVAL_METRICS", "bootstrap_interval", "PairedComparison",
    "compare_paired", "latency_ms", "CONDITIONS", "past_range", "frame_conditions", "ConditionScore",
    "score_conditions",
]

IOU_THRESHOLDS = np.linspace(0.0, 1.0, 101)
CE2D_THRESHOLDS = np.linspace(0.0, 50.0, 51)     # pixels, as OTB's precision plot
CE3D_THRESHOLDS = np.linspace(0.0, 4.0, 81)      # metres, 5 cm steps
KINDS = ("2d", "bev", "3d")
REACQUIRE_IOU = 0.3     # a return into view counts as re-acquired above this 2D IoU


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


AXES_3D = ("cx", "cy", "cz", "sx", "sy", "sz")   # a 3D box's coordinates, the order of bias_3d / mae_3d


def axis_errors_3d(pred3d: np.ndarray, gt3d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(bias, mae), each (6,) float64 in AXES_3D order: the mean and the mean absolute value of
    pred3d - gt3d (both (T, 6)) over the frames where both boxes are finite; nan where none is."""
    d = np.asarray(pred3d, np.float64).reshape(-1, 6) - np.asarray(gt3d, np.float64).reshape(-1, 6)
    d = d[np.all(np.isfinite(d), axis=1)]
    if not len(d):
        return np.full(6, np.nan), np.full(6, np.nan)
    return d.mean(axis=0), np.abs(d).mean(axis=0)


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
    two_d_only: bool = False        # no 3D boxes were scored: the 3D values are nan
    curves: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    bias_3d: list[float] = field(default_factory=lambda: [float("nan")] * 6)   # AXES_3D, metres
    mae_3d: list[float] = field(default_factory=lambda: [float("nan")] * 6)

    @property
    def fps(self) -> float:
        return self.timed_frames / self.tracker_seconds if self.tracker_seconds > 0 else float("nan")

    @property
    def fps_e2e(self) -> float:
        return self.timed_frames / self.e2e_seconds if self.e2e_seconds > 0 else float("nan")

    def summary(self) -> dict:
        """Plain values (no curves); a 2D-only score leaves out the 3D values it does not have."""
        d = {k: v for k, v in asdict(self).items()
             if k not in ("curves", "two_d_only") and not (self.two_d_only and k in _SCALARS_3D + _AXES)}
        d["fps"], d["fps_e2e"] = self.fps, self.fps_e2e
        return d


def latency_ms(ms) -> dict[str, float]:
    """{"ms_median", "ms_p99", "ms_max"} of per-update times `ms` (milliseconds, any shape; the
    p99 by numpy's linear interpolation); nan for no time."""
    a = np.asarray(ms, dtype=np.float64).reshape(-1)
    a = a[np.isfinite(a)]
    if not len(a):
        return {"ms_median": float("nan"), "ms_p99": float("nan"), "ms_max": float("nan")}
    return {"ms_median": float(np.median(a)), "ms_p99": float(np.percentile(a, 99)), "ms_max": float(a.max())}


def score_sequence(name: str, pred2d: np.ndarray, pred3d: np.ndarray | None, gt2d: np.ndarray,
                   gt3d: np.ndarray | None, scored: np.ndarray, restarts: int = 0, tracker_seconds: float = 0.0,
                   e2e_seconds: float = 0.0, timed_frames: int = 0,
                   image_size: tuple[int, int] | None = None) -> SequenceScore:
    """Score one sequence. pred2d/gt2d (T, 4), pred3d/gt3d (T, 6); scored (T,) bool marks the
    frames that count (present target, not an init frame). Predictions may be nan (no output).
    pred3d None: 2D only (the 3D values are nan, no 3D curves; gt3d is then not needed).
    image_size (width, height): a predicted 2D box's IoU is taken on its part in the image, as the
    labels are clipped to it (the GOT-10k toolkit's bound); its centre error on the box as given
    (a box wholly off the image clipped to a sliver on the border had been charged its distance
    from the border)."""
    two_d_only = pred3d is None
    pred2d = np.asarray(pred2d, np.float64).reshape(-1, 4)
    gt2d = np.asarray(gt2d, np.float64).reshape(-1, 4)
    scored = np.asarray(scored, bool).reshape(-1)
    n = len(scored)
    if two_d_only:   # nan boxes of the right length: the 3D formulas are skipped below
        pred3d = gt3d = np.full((n, 6), np.nan)
    pred3d = np.asarray(pred3d, np.float64).reshape(-1, 6)
    gt3d = np.asarray(gt3d, np.float64).reshape(-1, 6)
    if not (len(pred2d) == len(pred3d) == len(gt2d) == len(gt3d) == n):
        raise ValueError(f"sequence {name}: predictions, ground truth and flags differ in length "
                         f"({len(pred2d)}, {len(pred3d)}, {len(gt2d)}, {len(gt3d)}, {n})")
    p2, p3, g2, g3 = pred2d[scored], pred3d[scored], gt2d[scored], gt3d[scored]
    kinds = ("2d",) if two_d_only else KINDS
    ious = {"2d": iou_2d(p2 if image_size is None else clip_box2d(p2, *image_size), g2)}
    if not two_d_only:
        ious.update(bev=iou_bev(p3, g3), **{"3d": iou_3d(p3, g3)})
    with np.errstate(invalid="ignore"):
        ce2 = center_error_2d(p2, g2)
        ce3 = np.full(len(p3), np.nan) if two_d_only else center_error_3d(p3, g3)
    curves = {f"success_{k}": success_curve(ious[k]) for k in kinds}
    curves["precision_2d"] = precision_curve(ce2, CE2D_THRESHOLDS)
    if not two_d_only:
        curves["precision_3d"] = precision_curve(ce3, CE3D_THRESHOLDS)

    bias, mae = axis_errors_3d(p3, g3)

    def ao(k):
        return float(ious[k].mean()) if len(p2) and k in ious else float("nan")

    def sr(k, t):
        return float((ious[k] > t).mean()) if len(p2) and k in ious else float("nan")

    return SequenceScore(
        name=name, frames=int(scored.sum()), restarts=int(restarts),
        ao_2d=ao("2d"), sr50_2d=sr("2d", 0.5), sr75_2d=sr("2d", 0.75), ace_2d=_mean_or_nan(ce2),
        ao_bev=ao("bev"), sr50_bev=sr("bev", 0.5), sr75_bev=sr("bev", 0.75),
        ao_3d=ao("3d"), sr50_3d=sr("3d", 0.5), sr75_3d=sr("3d", 0.75), ace_3d=_mean_or_nan(ce3),
        tracker_seconds=float(tracker_seconds), e2e_seconds=float(e2e_seconds),
        timed_frames=int(timed_frames), two_d_only=two_d_only, curves=curves,
        bias_3d=[float(v) for v in bias], mae_3d=[float(v) for v in mae])


SCALARS_2D = ("ao_2d", "sr50_2d", "sr75_2d", "ace_2d")
_SCALARS_3D = ("ao_bev", "sr50_bev", "sr75_bev", "ao_3d", "sr50_3d", "sr75_3d", "ace_3d")
SCALARS = SCALARS_2D + _SCALARS_3D
ACE_KEYS = ("ace_2d", "ace_3d")
_AXES = ("bias_3d", "mae_3d")   # per-coordinate values (lists in AXES_3D order)


@dataclass
class OverallScore:
    """Averages over sequences (each sequence weighs the same); see module docstring."""

    sequences: int
    frames: int
    restarts: int
    values: dict[str, float]
    fps: float
    fps_e2e: float
    two_d_only: bool = False
    curves: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def summary(self) -> dict:
        """Plain values (no curves); a 2D-only score leaves out the 3D values it does not have."""
        values = {k: v for k, v in self.values.items() if not (self.two_d_only and k in _SCALARS_3D + _AXES)}
        return {"sequences": self.sequences, "frames": self.frames, "restarts": self.restarts,
                **values, "fps": self.fps, "fps_e2e": self.fps_e2e}


def average_scores(scores: list[SequenceScore]) -> OverallScore:
    """Mean over the sequences that have scored frames; restarts and times are summed."""
    used = [s for s in scores if s.frames > 0]
    if len({s.two_d_only for s in used}) > 1:   # their curves differ: a mean of such would be no one's
        raise ValueError("cannot average 2D-only and 3D sequence scores together: a sequence of a 3D run "
                         "without a 3D box is scored with nan boxes (IoU 0), not 2D only")
    values = {}
    for k in SCALARS:
        v = np.array([getattr(s, k) for s in used], dtype=np.float64)
        # a centre error is a mean over the sequences that all have one: a sequence without a box
        # on any scored frame would otherwise leave the mean, and outputting nothing on a hard
        # sequence would lower ACE (the paper averages every sequence); undefined then (nan)
        values[k] = (float("nan") if k in ACE_KEYS and not np.all(np.isfinite(v)) else _mean_or_nan(v))
    for k in _AXES:   # per coordinate, the mean over the sequences that have one
        a = np.array([getattr(s, k) for s in used], dtype=np.float64).reshape(-1, 6)
        values[k] = [_mean_or_nan(a[:, j]) for j in range(6)]
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
                        two_d_only=bool(used) and all(s.two_d_only for s in used), curves=curves)


@dataclass
class LostScore:
    """Lost-detection counts of one or more sequences (add them up with ``+``); see the module
    docstring. The rates are nan when their denominator is zero."""

    lost_true: int = 0          # frames reported lost where the target is absent
    lost_reported: int = 0      # frames reported lost
    absent_frames: int = 0      # frames where the target is absent
    returns: int = 0            # absent -> present transitions
    reacquired: int = 0         # returns followed by a good box within reacquire_frames

    def __add__(self, other: "LostScore") -> "LostScore":
        return LostScore(*(a + b for a, b in zip(astuple(self), astuple(other))))

    @property
    def precision(self) -> float:
        return self.lost_true / self.lost_reported if self.lost_reported else float("nan")

    @property
    def recall(self) -> float:
        return self.lost_true / self.absent_frames if self.absent_frames else float("nan")

    @property
    def reacquired_share(self) -> float:
        return self.reacquired / self.returns if self.returns else float("nan")

    def summary(self) -> dict:
        return {**asdict(self), "lost_precision": self.precision, "lost_recall": self.recall,
                "reacquired_share": self.reacquired_share}


def score_lost(lost: np.ndarray, absent: np.ndarray, pred2d: np.ndarray, gt2d: np.ndarray,
               reacquire_frames: int = 10) -> LostScore:
    """Lost detection over the tracked frames of one sequence (init frame excluded, the caller
    aligns them): lost (T,) bool, the tracker said "lost"; absent (T,) bool; pred2d / gt2d (T, 4).

    A return is a frame whose target is present after an absent one; it is re-acquired when some
    frame of the next `reacquire_frames` (the return included) is present, not lost, and has a
    2D IoU > REACQUIRE_IOU."""
    lost = np.asarray(lost, bool).reshape(-1)
    absent = np.asarray(absent, bool).reshape(-1)
    pred2d = np.asarray(pred2d, np.float64).reshape(-1, 4)
    gt2d = np.asarray(gt2d, np.float64).reshape(-1, 4)
    returns = reacquired = 0
    for i in range(1, len(absent)):
        if absent[i - 1] and not absent[i]:
            returns += 1
            window = np.arange(i, min(len(absent), i + reacquire_frames))
            good = window[~absent[window] & ~lost[window]]
            if len(good) and np.max(iou_2d(pred2d[good], gt2d[good])) > REACQUIRE_IOU:
                reacquired += 1
    return LostScore(lost_true=int(np.sum(lost & absent)), lost_reported=int(lost.sum()),
                     absent_frames=int(absent.sum()), returns=returns, reacquired=reacquired)


# Where the frames are (:func:`frame_conditions`, :func:`score_conditions`): each scored frame in
# one of these, from the ground truth alone. A range-limited depth sensor (ToF) sees only the near
# part of a body that reaches past its range, and the image border cuts a body that fills the
# view: the two conditions where the hidden extent is a guess.
CONDITIONS = ("whole", "past_range", "cut_by_image", "cut_and_past_range")


def past_range(gt3d: np.ndarray, range_m: float | None) -> np.ndarray:
    """(T,) bool: the box's far face lies beyond `range_m` metres (None: an unlimited sensor, all
    False) along the line of sight through the box's centre. gt3d (T, 6) [cx, cy, cz, sx, sy, sz],
    the camera frame; a box that is not finite or not in front of the camera is not past."""
    b = np.asarray(gt3d, np.float64).reshape(-1, 6)
    if range_m is None:
        return np.zeros(len(b), bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        far_z = b[:, 2] + b[:, 5] / 2.0
        stretch = np.sqrt((b[:, 0] / b[:, 2]) ** 2 + (b[:, 1] / b[:, 2]) ** 2 + 1.0)   # metres per metre of z
        out = (b[:, 2] > 0.0) & (far_z * stretch > float(range_m))
    return np.asarray(out & np.all(np.isfinite(b), axis=1), bool)


def frame_conditions(gt3d: np.ndarray, cut: np.ndarray, range_m: float | None) -> np.ndarray:
    """(T,) int, each frame's index into CONDITIONS: cut (T,) bool, the body reaches past the image
    border (the dataset's cut_by_image.label); past the depth range by :func:`past_range`."""
    c = np.asarray(cut, bool).reshape(-1)
    p = past_range(gt3d, range_m)
    if len(p) != len(c):
        raise ValueError(f"{len(p)} 3D boxes and {len(c)} cut flags")
    return (p.astype(np.int64) + 2 * c.astype(np.int64)).astype(np.int64)


@dataclass
class ConditionScore:
    """Sums over the scored frames of one condition, of one or more sequences (add them up with
    ``+``). The means pool the frames (each frame weighs the same, unlike the scores over
    sequences): a condition found in a few frames of some sequences has no per-sequence mean."""

    frames: int = 0
    iou_2d: float = 0.0       # sum over the frames
    iou_3d: float = 0.0
    ce_3d: float = 0.0        # sum over the frames with a 3D prediction
    ce_3d_frames: int = 0

    def __add__(self, other: "ConditionScore") -> "ConditionScore":
        return ConditionScore(*(a + b for a, b in zip(astuple(self), astuple(other))))

    def summary(self, total_frames: int, two_d_only: bool = False) -> dict:
        """frames, their share of `total_frames`, AO_2d, AO_3d, ACE_3d and the AO_3d lost there:
        the sum of (1 - IoU_3d) over these frames / total_frames (the shares of the conditions add
        up to 1 - AO_3d pooled over all frames); nan where there is nothing to divide by, the 3D
        values left out of a 2D-only score."""
        nan = float("nan")
        d = {"frames": self.frames, "share": self.frames / total_frames if total_frames else nan,
             "ao_2d": self.iou_2d / self.frames if self.frames else nan}
        if not two_d_only:
            d["ao_3d"] = self.iou_3d / self.frames if self.frames else nan
            d["ace_3d"] = self.ce_3d / self.ce_3d_frames if self.ce_3d_frames else nan
            d["ao_3d_lost"] = (self.frames - self.iou_3d) / total_frames if total_frames else nan
        return d


def score_conditions(pred2d: np.ndarray, pred3d: np.ndarray | None, gt2d: np.ndarray, gt3d: np.ndarray,
                     scored: np.ndarray, conditions: np.ndarray) -> dict[str, ConditionScore]:
    """One sequence's sums per condition (CONDITIONS order; every key present), over the scored
    frames: pred2d / gt2d (T, 4), pred3d / gt3d (T, 6) (pred3d None: 2D only, the 3D sums stay 0),
    scored (T,) bool as for :func:`score_sequence`, conditions (T,) int from :func:`frame_conditions`.
    A frame without a prediction counts IoU 0 and no centre error, as there."""
    pred2d = np.asarray(pred2d, np.float64).reshape(-1, 4)
    gt2d = np.asarray(gt2d, np.float64).reshape(-1, 4)
    gt3d = np.asarray(gt3d, np.float64).reshape(-1, 6)
    scored = np.asarray(scored, bool).reshape(-1)
    cond = np.asarray(conditions, np.int64).reshape(-1)
    n = len(scored)
    if not (len(pred2d) == len(gt2d) == len(gt3d) == len(cond) == n) or (
            pred3d is not None and len(np.asarray(pred3d).reshape(-1, 6)) != n):
        raise ValueError("predictions, ground truth, flags and conditions differ in length")
    i2 = np.zeros(n)
    i2[scored] = iou_2d(pred2d[scored], gt2d[scored])
    i3, ce = np.zeros(n), np.full(n, np.nan)
    if pred3d is not None:
        p3 = np.asarray(pred3d, np.float64).reshape(-1, 6)
        i3[scored] = iou_3d(p3[scored], gt3d[scored])
        with np.errstate(invalid="ignore"):
            ce[scored] = center_error_3d(p3[scored], gt3d[scored])
    out = {}
    for k, name in enumerate(CONDITIONS):
        m = scored & (cond == k)
        has = m & np.isfinite(ce)
        out[name] = ConditionScore(frames=int(m.sum()), iou_2d=float(i2[m].sum()), iou_3d=float(i3[m].sum()),
                                   ce_3d=float(ce[has].sum()), ce_3d_frames=int(has.sum()))
    return out


CI_LEVEL = 0.95              # the intervals' coverage
BOOTSTRAP_RESAMPLES = 10000  # resamples of the sequences (an AO interval's ends move by ~0.003 between seeds)
MOVED = 0.005                # a sequence counts as better or worse when its score moved by more than this
LOWER_IS_BETTER = frozenset({"ace_2d", "ace_3d"})
INTERVAL_METRICS = ("ao_2d", "ao_3d", "ace_3d")   # the per-sequence scores a report gives intervals of


def bootstrap_interval(values, level: float = CI_LEVEL, resamples: int = BOOTSTRAP_RESAMPLES,
                       seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval (lo, hi) of the mean of `values` (one per sequence; nan
    values dropped): the means of `resamples` draws of as many values with replacement, cut at
    (1 - level) / 2 on each side (numpy's "lower" / "higher" percentiles: the interval's ends are
    means a resample can take). (nan, nan) without values; (v, v) for one value."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    if int(resamples) < 1:
        raise ValueError(f"resamples must be >= 1, got {resamples}")
    if len(v) == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = v[rng.integers(0, len(v), size=(int(resamples), len(v)))].mean(axis=1)
    tail = (1.0 - level) / 2.0
    return (float(np.quantile(means, tail, method="lower")),
            float(np.quantile(means, 1.0 - tail, method="higher")))


@dataclass(frozen=True)
class PairedComparison:
    """One run against a baseline on the same sequences, for one per-sequence metric: `mean` of
    (run - baseline) over the `sequences` both have, its bootstrap interval [lo, hi] at `level`,
    and how many sequences got `better` / `worse` by more than `margin` (by the metric's sense)."""

    metric: str
    sequences: int
    mean: float
    lo: float
    hi: float
    better: int
    worse: int
    level: float = CI_LEVEL
    margin: float = MOVED

    def summary(self) -> dict:
        return asdict(self)


def compare_paired(metric: str, baseline: dict[str, float], run: dict[str, float], level: float = CI_LEVEL,
                   margin: float = MOVED, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = 0) -> PairedComparison:
    """`run` against `baseline`, both {sequence name: per-sequence value of `metric`}: paired over
    the sequences where both values are finite (see PairedComparison)."""
    names = [n for n in baseline if n in run and np.isfinite(baseline[n]) and np.isfinite(run[n])]
    d = np.array([float(run[n]) - float(baseline[n]) for n in names], dtype=np.float64)
    lo, hi = bootstrap_interval(d, level, resamples, seed)
    sign = -1.0 if metric in LOWER_IS_BETTER else 1.0
    return PairedComparison(metric=metric, sequences=len(d), mean=float(d.mean()) if len(d) else float("nan"),
                            lo=lo, hi=hi, better=int(np.sum(sign * d > margin)), worse=int(np.sum(sign * d < -margin)),
                            level=level, margin=margin)
