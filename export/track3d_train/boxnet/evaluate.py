"""Box-net evaluation over a frustum cache: the paper's "A3BoxNet" row (oracle 2D boxes).

Predictions go through the runtime decoding (`track3d.boxnet.decode_batch`); metrics follow
the paper's section III-C: IoUs and centre errors are averaged per sequence, then over
sequences (AO_bev, AO_3d, ACE_3d, SR@0.5/0.75 of the 3D IoU).
"""
from __future__ import annotations

import numpy as np

from track3d.boxes import iou_3d
from track3d.boxnet import OUTPUTS, one_hot
from track3d.size_coding import size_coding

from .data import PointCache

__all__ = ["predict", "oracle_metrics", "torch_runner", "onnx_runner"]


def torch_runner(model):
    import torch

    model.eval()

    def run(centred: np.ndarray, cat: np.ndarray):
        with torch.no_grad():
            out = model(torch.from_numpy(centred), torch.from_numpy(cat))
        return [o.numpy() for o in out]
    return run


def onnx_runner(est):
    """est: a track3d.boxnet.A3BoxNetEstimator."""
    def run(centred: np.ndarray, cat: np.ndarray):
        feeds = {"points": centred}
        if est._with_category:
            feeds["category"] = cat
        return est.model.run(feeds, list(OUTPUTS))
    return run


def predict(run, cache: PointCache, num_points: int, num_categories: int = 3, batch: int = 64,
            seed: int = 12345, zero_category: bool = False, size_norm: str = "points") -> np.ndarray:
    """(len(cache), 6) boxes. Sampling: the runtime sampler with seed `seed` for every item
    (what the runtime estimator does); the whole frustum's bounds from the cache."""
    from track3d.frustum import sample_points

    coding = size_coding(size_norm)
    base = cache.field("baseline")
    out = np.zeros((len(cache), 6))
    for s in range(0, len(cache), batch):
        idx = list(range(s, min(s + batch, len(cache))))
        pts = np.stack([sample_points(cache.points(i), num_points, seed) for i in idx])
        b = base[idx]
        bounds = np.stack([b[:, :3] - b[:, 3:] / 2, b[:, :3] + b[:, 3:] / 2], axis=1)
        centred, ref, scale = coding.normalise(pts, bounds)
        cats = cache.category[cache.index[idx]]
        cat = one_hot(np.full_like(cats, -1) if zero_category else cats, num_categories)
        out[s:s + len(idx)] = coding.decode(ref, scale, *run(centred, cat))
    return out


def oracle_metrics(pred: np.ndarray, gt: np.ndarray, seq: np.ndarray, gt2d: np.ndarray | None = None) -> dict:
    """Per-sequence scores averaged over sequences with the runtime's evaluation toolkit
    (`track3d.evaluation.metrics`, paper section III-C); the 2D box is the oracle's (ground truth)."""
    from track3d.evaluation.metrics import average_scores, score_sequence

    pred, gt, seq = np.asarray(pred, np.float64), np.asarray(gt, np.float64), np.asarray(seq)
    g2 = np.tile([0.0, 0.0, 1.0, 1.0], (len(gt), 1)) if gt2d is None else np.asarray(gt2d, np.float64)
    scores = [score_sequence(str(s), g2[seq == s], pred[seq == s], g2[seq == s], gt[seq == s],
                             np.ones(int((seq == s).sum()), bool)) for s in np.unique(seq)]
    v = average_scores(scores).values
    return {"AO_bev": v["ao_bev"], "AO_3d": v["ao_3d"], "ACE_3d": v["ace_3d"], "SR50_3d": v["sr50_3d"],
            "SR75_3d": v["sr75_3d"], "SR50_bev": v["sr50_bev"], "frames": int(len(gt)),
            "sequences": len(scores), "frame_mean_iou3d": float(iou_3d(pred, gt).mean())}
