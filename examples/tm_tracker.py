"""An example track3d plug-in: a template-matching 2D tracker registered as "tm".

Use it from the CLI (the module registers itself when imported)::

    track3d trackers --plugin examples/tm_tracker.py
    track3d track --plugin examples/tm_tracker.py --tracker tm --estimator baseline --data DATA
    track3d track --plugin tm_tracker ...        # when the folder is on PYTHONPATH

or ship it in a package with an entry point (pyproject.toml)::

    [project.entry-points."track3d.trackers"]
    tm = "tm_tracker:TemplateTracker"

The protocol is OpenCV's: ``init(image, box)``, ``update(image) -> (ok, box)``; images are
(H, W, 3) uint8 RGB, boxes [x, y, w, h]. Optional extras the loop uses: ``score`` (0..1, this
frame's confidence), ``correct(box)`` (adopt the fused box), ``get_state()`` / ``set_state()``
(checkpoints, numpy arrays and builtins).
"""
from __future__ import annotations

import cv2
import numpy as np

from track3d.trackers2d import register_tracker


class TemplateTracker:
    """Normalised cross-correlation of the first frame's patch within a window around the last box.

    Options: search (window size as a multiple of the box, default 2.0), min_score (below it
    the target counts as not found, default 0.3)."""

    def __init__(self, search: float = 2.0, min_score: float = 0.3):
        if search < 1.0:
            raise ValueError(f"search must be >= 1, got {search}")
        self.search = float(search)
        self.min_score = float(min_score)
        self.template: np.ndarray | None = None
        self.box = np.full(4, np.nan)
        self.score: float | None = None

    def init(self, image: np.ndarray, box) -> None:
        b = np.asarray(box, dtype=np.float64).reshape(4)
        x, y, w, h = (int(round(v)) for v in b)
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        x0, y0 = max(x, 0), max(y, 0)   # the part of the box inside the image
        self.template = gray[y0:max(y + h, y0 + 1), x0:max(x + w, x0 + 1)].copy()
        self.box = np.array([x0, y0, self.template.shape[1], self.template.shape[0]], np.float64)
        self.score = None

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        if self.template is None or self.template.size == 0:
            return False, self.box.copy()
        gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
        th, tw = self.template.shape
        cx, cy = self.box[0] + self.box[2] / 2, self.box[1] + self.box[3] / 2
        half_w, half_h = self.search * tw / 2, self.search * th / 2
        x0, y0 = int(max(cx - half_w, 0)), int(max(cy - half_h, 0))
        x1, y1 = int(min(cx + half_w, gray.shape[1])), int(min(cy + half_h, gray.shape[0]))
        window = gray[y0:y1, x0:x1]
        if window.shape[0] < th or window.shape[1] < tw:
            self.score = 0.0
            return False, self.box.copy()
        r = cv2.matchTemplate(window, self.template, cv2.TM_CCOEFF_NORMED)
        _, peak, _, loc = cv2.minMaxLoc(r)
        self.score = float(np.clip(peak, 0.0, 1.0)) if np.isfinite(peak) else 0.0
        if self.score < self.min_score:
            return False, self.box.copy()
        self.box = np.array([x0 + loc[0], y0 + loc[1], tw, th], np.float64)
        return True, self.box.copy()

    def correct(self, box) -> None:
        """Adopt the fused box's position (the template keeps its size)."""
        b = np.asarray(box, dtype=np.float64).reshape(4)
        if np.all(np.isfinite(b)):
            self.box[:2] = b[:2] + b[2:] / 2 - self.box[2:] / 2

    def get_state(self) -> dict:
        return {"template": None if self.template is None else self.template.copy(), "box": self.box.copy(),
                "score": self.score}

    def set_state(self, state: dict) -> None:
        t = state["template"]
        self.template = None if t is None else np.asarray(t, dtype=np.uint8).copy()
        self.box = np.asarray(state["box"], dtype=np.float64).reshape(4).copy()
        self.score = state["score"]


register_tracker("tm", TemplateTracker)
