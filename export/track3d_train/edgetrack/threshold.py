"""Fit EdgeTrack's lost threshold (and the weight of its motion prediction) on held-out
sequences, and write them into the model's metadata.

The motion weight (``motion``: how much of the smoothed frame-to-frame motion moves the search
centre, `track3d.edgetrack`) is chosen first, by one-pass AO_2d at the model's threshold:
following a fast body is what it is for. The threshold is then fitted at that motion.

The threshold decides when `update` says the target is lost (ok=False, wider search). It is
fitted by running the tracker one pass at each candidate threshold (the threshold changes
what the tracker does next, so a post-hoc cut of recorded scores would not be the same
tracker) on sequences that are neither the training data nor a test split, scoring the
"lost" reports against the absent frames (`track3d.evaluation`, ``LostScore``): the F1 of
lost-vs-absent decides, AO_2d breaks ties. Measured on the shipped model: a threshold of
0.5 flags frames it tracks with IoU > 0.5; absent frames score below 0.02.
"""
from __future__ import annotations

import math
from pathlib import Path

__all__ = ["fit_threshold", "fit_motion", "fit_reacquire", "write_threshold"]


def _f1(p: float, r: float) -> float:
    if not (math.isfinite(p) and math.isfinite(r)) or p + r == 0:
        return 0.0
    return 2 * p * r / (p + r)


def _roots(data) -> list:
    return list(data) if isinstance(data, (list, tuple)) else [data]


def _pooled(data, split: str, specs, max_sequences: int | None, quiet: bool) -> dict[str, dict]:
    """evaluate_2d of `specs` on every dataset root of `data`, pooled: AO_2d weighted by the
    sequences, the lost counts added up (precision and recall from the sums)."""
    from track3d.evaluation import evaluate_2d
    from track3d.evaluation.metrics import LostScore

    runs = [evaluate_2d(root, split, specs, max_sequences=max_sequences, quiet=quiet) for root in _roots(data)]
    out = {}
    for spec in specs:
        rs = [r[spec.label] for r in runs]
        n = sum(r["sequences"] for r in rs)
        lost = sum((LostScore(**{k: r[k] for k in ("lost_true", "lost_reported", "absent_frames", "returns",
                                                    "reacquired")}) for r in rs), LostScore())
        out[spec.label] = {"sequences": n, "ao_2d": sum(r["ao_2d"] * r["sequences"] for r in rs) / n,
                           **lost.summary()}
    return out


def fit_motion(model: str | Path, data: str | Path, split: str, grid: list[float], threads: int = 1,
               max_sequences: int | None = None, quiet: bool = True) -> dict:
    """{"motion": best, "rows": [{motion, ao_2d, lost_precision, lost_recall}]}: one pass per
    candidate at the model's own threshold on `data` (one dataset root or several, pooled); the
    best one-pass AO_2d wins (the smaller weight on a tie)."""
    from track3d.evaluation import TrackerSpec

    if not grid or any(not 0.0 <= m <= 2.0 for m in grid):
        raise ValueError(f"motion weights must lie in [0, 2], got {grid}")
    specs = [TrackerSpec("edgetrack", "none", threads=threads, name=f"motion {m:g}",
                         tracker_options={"model": str(model), "motion": float(m)}) for m in grid]
    res = _pooled(data, split, specs, max_sequences, quiet)
    rows = [{"motion": float(m), **{k: res[s.label].get(k) for k in ("ao_2d", "lost_precision", "lost_recall")}}
            for m, s in zip(grid, specs)]
    best = max(rows, key=lambda x: (round(x["ao_2d"], 6), -x["motion"]))
    return {"motion": best["motion"], "rows": rows}


def fit_threshold(model: str | Path, data: str | Path, split: str, grid: list[float], threads: int = 1,
                  max_sequences: int | None = None, quiet: bool = True, motion: float | None = None) -> dict:
    """{"threshold": best, "rows": [{threshold, f1, lost_precision, lost_recall, ao_2d, ...}]};
    data: one dataset root or several (pooled); motion: the motion weight to run with (None: the
    model's own)."""
    from track3d.evaluation import TrackerSpec

    if not grid or any(not 0.0 < t < 1.0 for t in grid):
        raise ValueError(f"thresholds must lie in (0, 1), got {grid}")
    extra = {} if motion is None else {"motion": float(motion)}
    specs = [TrackerSpec("edgetrack", "none", threads=threads, name=f"th {t:g}",
                         tracker_options={"model": str(model), "score_threshold": float(t), **extra}) for t in grid]
    res = _pooled(data, split, specs, max_sequences, quiet)
    rows = []
    for t, spec in zip(grid, specs):
        r = res[spec.label]
        if not r.get("absent_frames"):
            raise ValueError(f"{data} {split}: no absent frames, nothing to fit a lost threshold on")
        rows.append({"threshold": float(t), "f1": _f1(r["lost_precision"], r["lost_recall"]),
                     **{k: r[k] for k in ("lost_precision", "lost_recall", "lost_reported", "absent_frames",
                                          "ao_2d", "reacquired_share")}})
    best = max(rows, key=lambda x: (round(x["f1"], 6), x["ao_2d"]))
    return {"threshold": best["threshold"], "rows": rows}


def fit_reacquire(model: str | Path, data: str | Path, split: str, grid: list[float], threshold: float,
                  threads: int = 1, max_sequences: int | None = None, quiet: bool = True,
                  motion: float | None = None) -> dict:
    """{"reacquire_threshold": best, "rows": [...]}: one pass per value at the lost `threshold`
    (values below it are the threshold itself: dropped); the F1 of lost vs absent frames decides,
    then AO_2d, then the lower value."""
    from track3d.evaluation import TrackerSpec

    grid = [float(r) for r in grid if float(r) >= threshold]
    if not grid or any(not 0.0 < r <= 1.0 for r in grid):
        raise ValueError(f"re-acquisition thresholds must lie in [{threshold:g}, 1] (the lost threshold and above)")
    extra = {} if motion is None else {"motion": float(motion)}
    specs = [TrackerSpec("edgetrack", "none", threads=threads, name=f"re {r:g}",
                         tracker_options={"model": str(model), "score_threshold": float(threshold),
                                          "reacquire_threshold": r, **extra}) for r in grid]
    res = _pooled(data, split, specs, max_sequences, quiet)
    rows = [{"reacquire_threshold": r, "f1": _f1(res[s.label]["lost_precision"], res[s.label]["lost_recall"]),
             **{k: res[s.label][k] for k in ("lost_precision", "lost_recall", "ao_2d", "reacquired_share")}}
            for r, s in zip(grid, specs)]
    best = max(rows, key=lambda x: (round(x["f1"], 6), round(x["ao_2d"], 6), -x["reacquire_threshold"]))
    return {"reacquire_threshold": best["reacquire_threshold"], "rows": rows}


def write_threshold(model: str | Path, threshold: float, note: dict, motion: float | None = None,
                    reacquire: float | None = None) -> list[Path]:
    """Rewrite the threshold (tracking default and score block) of <model>_template/_search.onnx,
    and the motion weight and the re-acquisition threshold when given, weights untouched; ``note`` (data, split, rows) goes to
    ``score.threshold_fit``. Its int8 twins (the old threshold) are removed."""
    import onnx

    from ..onnx_meta import read_metadata, remove_stale_twins, rewrite_metadata, twins_of

    paths = [Path(f"{model}_template.onnx"), Path(f"{model}_search.onnx")]
    for p in paths:
        try:
            meta = read_metadata(onnx.load(str(p)))
        except ValueError as e:
            raise ValueError(f"{p}: {e}") from None
        if "tracking" in meta:
            meta["tracking"]["score_threshold"] = float(threshold)
            if motion is not None:
                meta["tracking"]["motion"] = float(motion)
            if reacquire is not None:
                meta["tracking"]["reacquire_threshold"] = float(reacquire)
        if "score" in meta:
            meta["score"]["threshold"] = float(threshold)
            meta["score"]["threshold_fit"] = note
        rewrite_metadata(p, meta)
    # an int8 twin beside them keeps the old threshold and the old file's sha256 (the runtime
    # refuses it from now on): removed with one line each, as an export --force removes it
    remove_stale_twins(twins_of(paths))
    return paths
