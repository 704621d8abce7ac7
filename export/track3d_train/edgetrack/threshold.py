"""Fit EdgeTrack's lost threshold on held-out sequences, and write it into the model's metadata.

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

__all__ = ["fit_threshold", "write_threshold"]


def _f1(p: float, r: float) -> float:
    if not (math.isfinite(p) and math.isfinite(r)) or p + r == 0:
        return 0.0
    return 2 * p * r / (p + r)


def fit_threshold(model: str | Path, data: str | Path, split: str, grid: list[float], threads: int = 1,
                  max_sequences: int | None = None, quiet: bool = True) -> dict:
    """{"threshold": best, "rows": [{threshold, f1, lost_precision, lost_recall, ao_2d, ...}]}."""
    from track3d.evaluation import TrackerSpec, evaluate_2d

    if not grid or any(not 0.0 < t < 1.0 for t in grid):
        raise ValueError(f"thresholds must lie in (0, 1), got {grid}")
    specs = [TrackerSpec("edgetrack", "none", threads=threads, name=f"th {t:g}",
                         tracker_options={"model": str(model), "score_threshold": float(t)}) for t in grid]
    res = evaluate_2d(data, split, specs, max_sequences=max_sequences, quiet=quiet)
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


def write_threshold(model: str | Path, threshold: float, note: dict) -> list[Path]:
    """Rewrite the threshold (tracking default and score block) of <model>_template/_search.onnx,
    weights untouched; ``note`` (data, split, rows) goes to ``score.threshold_fit``."""
    import json

    import onnx

    from track3d.onnxmodel import META_KEY

    from ..onnx_meta import rewrite_metadata

    paths = [Path(f"{model}_template.onnx"), Path(f"{model}_search.onnx")]
    for p in paths:
        props = {e.key: e.value for e in onnx.load(str(p)).metadata_props}
        if META_KEY not in props:
            raise ValueError(f"{p}: no track3d metadata")
        meta = json.loads(props[META_KEY])
        if "tracking" in meta:
            meta["tracking"]["score_threshold"] = float(threshold)
        if "score" in meta:
            meta["score"]["threshold"] = float(threshold)
            meta["score"]["threshold_fit"] = note
        rewrite_metadata(p, meta)
    return paths
