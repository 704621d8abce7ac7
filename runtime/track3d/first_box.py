"""The hidden depth of a body whose first 3D box is known.

One view shows the near side of a body only, and the depth of its far side is the loop's largest
error on shapes unlike the training ones (issue 12: ideal depth, held-out shapes, oracle 2D boxes,
mean |size z error| 0.9 m over 60 frames). 3D single-object tracking benchmarks start a tracker
from the first frame's 3D box (KITTI's protocol, P2B and its successors), and a spacecraft that has
mapped the body on its approach can too. Then the depth extent is known at the start, and it holds
while the body has not turned. The sensor sees the body's lateral extents (x, y) at every frame
but not its rotation: when they have moved away from the first box's, the body has turned and its
depth along the line of sight has changed with them. `first_box_weight` is the share the first
box's depth keeps: 1 at the first box's lateral extents, falling linearly with their largest
relative change to 0 at `fade`; `with_first_depth` blends the depths, the front face kept (the
sensor sees it).
"""
from __future__ import annotations

import numpy as np

__all__ = ["FIRST_BOX_FADE", "first_box_weight", "with_first_depth", "check_fade"]

# The relative change of the lateral extents at which the first box's depth no longer counts;
# chosen by measurement (docs/runtime.md, "A known first 3D box").
FIRST_BOX_FADE = 0.2


def check_fade(fade) -> float:
    """`fade` as a float in (0, 10], or ValueError."""
    try:
        f = float(fade)
    except (TypeError, ValueError):
        f = float("nan")
    if not 0.0 < f <= 10.0:
        raise ValueError(f"first_box_fade must be in (0, 10] (a relative change of the lateral extents), got {fade!r}")
    return f


def first_box_weight(box: np.ndarray, first: np.ndarray, fade: float = FIRST_BOX_FADE) -> float:
    """The weight (0..1) of the first box's depth extent in `box` (6,) [cx, cy, cz, sx, sy, sz]:
    1 - max(|sx / sx0 - 1|, |sy / sy0 - 1|) / fade, clipped to [0, 1]; 0 for a box that is not
    finite."""
    sx, sy = float(box[3]), float(box[4])
    if not (np.isfinite(sx) and np.isfinite(sy)):
        return 0.0
    change = max(abs(sx / float(first[3]) - 1.0), abs(sy / float(first[4]) - 1.0))
    return float(min(max(1.0 - change / fade, 0.0), 1.0))


def with_first_depth(box: np.ndarray, first: np.ndarray, fade: float = FIRST_BOX_FADE) -> np.ndarray:
    """`box` (6,) with its depth extent w * first's + (1 - w) * its own (w: `first_box_weight`),
    its front face (cz - sz / 2) where it was; a new (6,) float64 array."""
    out = np.array(box, dtype=np.float64)
    w = first_box_weight(out, first, fade)
    if w > 0.0 and np.isfinite(out[2]) and np.isfinite(out[5]):
        front = out[2] - out[5] / 2.0
        out[5] = w * float(first[5]) + (1.0 - w) * out[5]
        out[2] = front + out[5] / 2.0
    return out
