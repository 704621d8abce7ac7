"""Textured image the stereo depth did not match: not the tracked body.

Stereo depth has a return wherever a surface near enough has texture (`track3d.stereo`: the
matcher's texture test, d >= min_disparity). Its outline of the body is therefore only the lit,
textured part, and the loop lets the 2D box reach past it (the dark side has no texture and no
depth: `silhouette.contain`). Texture *without* returns next to that outline is different: it
is a surface too far to match (a moon or a planet's limb in the background, a dense star field),
and a 2D tracker that spreads its box over it (EdgeTrack over a textured moon half behind the
body: IoU_2d 0.93 -> 0.75 over 100 frames) is pulled back by `trim_unmatched`.

Two cases look alike and are kept out:
- a body whose own texture is mostly unmatched (a dark body: stereo returns on a few percent of
  its pixels): the rule stands down unless the returns number at least MATCH_COVER of the
  textured pixels inside the outline;
- the band at the left image border that the right camera does not see (a left pixel u
  matches the right pixel u - d: no match for u < d, d = fx * baseline / z of the body's
  nearest return): a near body cut by the left border has texture there and no depth.

Texture is the local standard deviation of the grey image over TEXTURE_BLOCK x TEXTURE_BLOCK
pixels, relative to the outline's own (TEXTURE_REL x its 90th percentile), so the rule does not
depend on exposure. Glare, stray light and a nebula's glow are smooth: not texture.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["TEXTURE_BLOCK", "TEXTURE_REL", "TEXTURE_SHARE", "MATCH_COVER", "MIN_TEXTURE_DN", "trim_unmatched"]

TEXTURE_BLOCK = 5       # pixels: the side of the block whose grey standard deviation is texture
TEXTURE_REL = 0.3       # a pixel is textured at this share of the outline's texture level or more
TEXTURE_SHARE = 0.4     # a column (row) beyond the outline with this share textured ends the box
MATCH_COVER = 0.5       # returns per textured outline pixel below which the rule stands down
MIN_TEXTURE_DN = 5.0    # an outline whose texture level (grey std, DN) is below this: no rule


def _first(profile: np.ndarray, share: float) -> int | None:
    """Index of the first entry of `profile` at `share` or more, None if there is none."""
    hit = np.flatnonzero(profile >= share)
    return int(hit[0]) if len(hit) else None


def _low_side(profile: np.ndarray, origin: int, edge: float, side: float) -> float:
    """A low side (left, top) at `side` pulled in: `profile` (per column or row from `origin`)
    scanned from the one before `edge` (the outline's side less the slack) down to `side`; the
    side moves to just past the first entry at TEXTURE_SHARE or more, else stays."""
    s, e = min(int(np.floor(edge)) - origin, len(profile)), max(int(np.floor(side)) - origin, 0)
    k = _first(profile[e:s][::-1], TEXTURE_SHARE) if s > e else None
    return side if k is None else float(origin + s - k)


def _high_side(profile: np.ndarray, origin: int, edge: float, side: float) -> float:
    """A high side (right, bottom) at `side` pulled in: scanned from `edge` up to `side`; the side
    moves to the first entry at TEXTURE_SHARE or more, else stays."""
    s, e = max(int(np.ceil(edge)) - origin, 0), min(int(np.ceil(side)) - origin, len(profile))
    k = _first(profile[s:e], TEXTURE_SHARE) if e > s else None
    return side if k is None else float(origin + s + k)


def trim_unmatched(box: np.ndarray, lit: np.ndarray, image: np.ndarray, returns: int,
                   blind_px: float = 0.0, slack: float = 2.0) -> np.ndarray:
    """The 2D box (4,) float64 [x, y, w, h] with each side that reaches past the stereo outline
    `lit` [x, y, w, h] (by more than `slack` px) pulled in to the first column (row), going out
    from the outline, where TEXTURE_SHARE of the pixels across the outline's rows (columns) are
    textured: texture the depth did not match. `box` holds `lit` (`silhouette.contain`).

    image: (H, W, 3) uint8 RGB, the frame the outline is of; returns: the body's returns around
    the box (the outline's); blind_px: columns left of this are not seen by the right camera
    (fx * baseline / nearest depth), never texture here. The box as it was when the rule stands
    down (see the module's notes) or nothing is found."""
    b = np.array(box, dtype=np.float64).reshape(4)
    o = np.asarray(lit, dtype=np.float64).reshape(4)
    H, W = image.shape[:2]
    x0, y0, x1, y1 = b[0], b[1], b[0] + b[2], b[1] + b[3]
    lx0, ly0, lx1, ly1 = o[0], o[1], o[0] + o[2], o[1] + o[3]
    reach = (x0 < lx0 - slack, y0 < ly0 - slack, x1 > lx1 + slack, y1 > ly1 + slack)
    if not any(reach):
        return b
    # the image the rule reads: the outline and the box's parts beyond it, clipped to the frame
    rx0, ry0 = int(max(np.floor(min(x0, lx0)), 0)), int(max(np.floor(min(y0, ly0)), 0))
    rx1, ry1 = int(min(np.ceil(max(x1, lx1)), W)), int(min(np.ceil(max(y1, ly1)), H))
    ox0, oy0 = int(max(np.floor(lx0), rx0)) - rx0, int(max(np.floor(ly0), ry0)) - ry0
    ox1, oy1 = int(min(np.ceil(lx1), rx1)) - rx0, int(min(np.ceil(ly1), ry1)) - ry0
    if ox1 - ox0 < TEXTURE_BLOCK or oy1 - oy0 < TEXTURE_BLOCK:
        return b
    grey = cv2.cvtColor(np.ascontiguousarray(image[ry0:ry1, rx0:rx1]), cv2.COLOR_RGB2GRAY)
    k = (TEXTURE_BLOCK, TEXTURE_BLOCK)
    mean = cv2.boxFilter(grey, cv2.CV_32F, k)
    var = cv2.sqrBoxFilter(grey, cv2.CV_32F, k) - mean * mean     # local variance, DN^2
    inside = var[oy0:oy1, ox0:ox1]
    level = float(np.percentile(inside[::2, ::2], 90))
    if not level >= MIN_TEXTURE_DN ** 2:
        return b
    textured = var >= np.float32(TEXTURE_REL ** 2 * level)
    if returns < MATCH_COVER * float(np.count_nonzero(textured[oy0:oy1, ox0:ox1])):
        return b   # the body's own texture is mostly unmatched: unmatched texture says nothing
    cols = textured[oy0:oy1].mean(axis=0)                        # per column of [rx0, rx1)
    rows = textured[:, ox0:ox1].mean(axis=1)                     # per row of [ry0, ry1)
    blind = int(np.ceil(blind_px)) - rx0
    if blind > 0:
        cols[:blind] = 0.0
    if reach[0]:   # left: from the outline's left edge (less the slack) outwards
        x0 = _low_side(cols, rx0, lx0 - slack, x0)
    if reach[2]:   # right
        x1 = _high_side(cols, rx0, lx1 + slack, x1)
    if reach[1]:   # top
        y0 = _low_side(rows, ry0, ly0 - slack, y0)
    if reach[3]:   # bottom
        y1 = _high_side(rows, ry0, ly1 + slack, y1)
    out = b.copy()   # an axis left as it was keeps its numbers (x + w - x need not give w back)
    if (x0, x1) != (b[0], b[0] + b[2]):
        out[0], out[2] = x0, x1 - x0
    if (y0, y1) != (b[1], b[1] + b[3]):
        out[1], out[3] = y0, y1 - y0
    return out
