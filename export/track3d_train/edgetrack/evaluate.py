"""One-pass evaluation of EdgeTrack (and any other 2D tracker) with lost detection scored.

AO_2d / SR / ACE come from the project's one-pass protocol (`siamfc.evaluate.run_sequence`:
init on the first frame with the target present, no restart, absent frames not scored). On top
of it, every `update`'s ok flag is recorded, and 'lost' (ok=False) is scored against the
sequence's absence labels: precision and recall of lost on absent frames, and re-acquisition:
the share of the target's returns into view after which the tracker has IoU > 0.3 within
`reacquire_frames` frames.
"""
from __future__ import annotations

import numpy as np

from track3d.boxes import iou_2d

from ..siamfc.evaluate import load_frames, run_sequence, summarise

__all__ = ["OkRecorder", "lost_scores", "evaluate_tracker"]


class OkRecorder:
    """Wraps a 2D tracker and records the ok flag of each update."""

    def __init__(self, tracker):
        self.tracker = tracker
        self.oks: list[bool] = []

    def init(self, image, box):
        self.oks = []
        self.tracker.init(image, box)

    def update(self, image):
        ok, box = self.tracker.update(image)
        self.oks.append(bool(ok))
        return ok, box


def lost_scores(oks: np.ndarray, absent: np.ndarray, pred: np.ndarray, gt: np.ndarray,
                reacquire_frames: int = 10) -> dict:
    """Counts over the updated frames (oks[k] belongs to frame first + 1 + k, aligned by the
    caller): true / false 'lost', absent frames, and returns into view re-acquired."""
    lost = ~np.asarray(oks, bool)
    absent = np.asarray(absent, bool)
    tp = int(np.sum(lost & absent))
    returns, reacq = 0, 0
    for i in range(1, len(absent)):
        if absent[i - 1] and not absent[i]:
            returns += 1
            j1 = min(len(absent), i + reacquire_frames)
            idx = [j for j in range(i, j1) if not absent[j] and not lost[j]]
            if idx and np.max(iou_2d(pred[idx], gt[idx])) > 0.3:
                reacq += 1
    return {"lost_true": tp, "lost_reported": int(lost.sum()), "absent_frames": int(absent.sum()),
            "returns": returns, "reacquired": reacq}


def evaluate_tracker(make_tracker, sequences, reacquire_frames: int = 10, progress: bool = False) -> dict:
    """One-pass summary (AO_2d, SR_0.5, ACE_2d, ms per update) plus lost precision / recall."""
    results, counts = [], []
    it = sequences
    if progress:
        from tqdm import tqdm
        it = tqdm(sequences, desc="sequences", unit="seq")
    for seq in it:
        rec = OkRecorder(make_tracker())
        frames = load_frames(seq)
        r = run_sequence(rec, frames, seq.gt2d, seq.absent)
        results.append(r)
        if r["frames"] == 0:
            continue
        first = len(seq) - 1 - r["frames"]
        sl = slice(first + 1, len(seq))
        counts.append(lost_scores(np.array(rec.oks), seq.absent[sl], r["pred"][sl], seq.gt2d[sl], reacquire_frames))
    out = summarise(results)
    out.pop("success_curve", None)
    out.pop("precision_curve", None)
    tot = {k: sum(c[k] for c in counts) for k in ("lost_true", "lost_reported", "absent_frames", "returns", "reacquired")}
    out.update(tot)
    out["lost_precision"] = tot["lost_true"] / tot["lost_reported"] if tot["lost_reported"] else float("nan")
    out["lost_recall"] = tot["lost_true"] / tot["absent_frames"] if tot["absent_frames"] else float("nan")
    out["reacquired_share"] = tot["reacquired"] / tot["returns"] if tot["returns"] else float("nan")
    return out
