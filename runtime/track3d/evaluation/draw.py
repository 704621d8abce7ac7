"""Overlay drawing (cv2) and overlay writers (GIF via pillow when available, else MP4).

Colours (RGB): ground truth green, the 2D tracker's raw box yellow, the reported (fused) box
red, the projected 3D box cyan (its 12 edges), the 3D ground truth thin green edges.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..camera import Camera

__all__ = ["box3d_corners", "draw_overlay", "OverlayWriter"]

GT, RAW, FUSED, BOX3D = (0, 200, 0), (230, 200, 0), (230, 30, 30), (0, 200, 230)
_EDGES = [(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4), (0, 4), (1, 5), (2, 6), (3, 7)]


def box3d_corners(box3d: np.ndarray) -> np.ndarray:
    """(8, 3) corners of an axis-aligned [cx, cy, cz, sx, sy, sz] box; corner k has bit 0 = +x,
    bit 1 = +y, bit 2 = +z (for drawing only: overlaps are computed in track3d.boxes)."""
    b = np.asarray(box3d, np.float64).reshape(6)
    bits = np.array([[(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], np.float64)
    return b[:3] + (bits - 0.5) * b[3:]


def _drawn(box) -> bool:
    """Whether `_rect` (a (4,) box) or `_cube` (a (6,) box) draws `box`: finite, of positive size."""
    if box is None:
        return False
    b = np.asarray(box, np.float64)
    return b.shape in ((4,), (6,)) and bool(np.all(np.isfinite(b))) and bool(np.all(b[2 if len(b) == 4 else 3:] > 0))


def _rect(img, box, color, thickness):
    b = np.asarray(box, np.float64)
    if b.shape == (4,) and _drawn(b):
        p0 = (int(round(b[0])), int(round(b[1])))
        p1 = (int(round(b[0] + b[2])), int(round(b[1] + b[3])))
        cv2.rectangle(img, p0, p1, color, thickness, cv2.LINE_AA)


def _cube(img, camera, box3d, color, thickness):
    b = np.asarray(box3d, np.float64)
    if b.shape != (6,) or not _drawn(b):
        return
    c = box3d_corners(b)
    uv = camera.project(c)
    for i, j in _EDGES:
        if c[i, 2] > 0.05 and c[j, 2] > 0.05 and np.all(np.abs(uv[[i, j]]) < 1e5):
            cv2.line(img, tuple(int(round(x)) for x in uv[i]), tuple(int(round(x)) for x in uv[j]),
                     color, thickness, cv2.LINE_AA)


def draw_overlay(image: np.ndarray, camera: Camera, box2d: np.ndarray | None = None,
                 box2d_raw: np.ndarray | None = None, box3d: np.ndarray | None = None,
                 gt2d: np.ndarray | None = None, gt3d: np.ndarray | None = None, text: str = "") -> np.ndarray:
    """A copy of `image` (H, W, 3) uint8 RGB with the boxes drawn (any of them may be None)."""
    img = np.ascontiguousarray(image).copy()
    if gt3d is not None:
        _cube(img, camera, gt3d, GT, 1)
    if gt2d is not None:
        _rect(img, gt2d, GT, 1)
    if box3d is not None:
        _cube(img, camera, box3d, BOX3D, 1)
    if box2d_raw is not None:
        _rect(img, box2d_raw, RAW, 1)
    if box2d is not None:
        _rect(img, box2d, FUSED, 2)
    if text:
        cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    # the colour key, of the boxes drawn (a nan box, as a 2D-only run's 3D box, is not drawn):
    # an overlay is often looked at far from these docs
    key = [(name, colour) for name, colour, boxes in (("truth", GT, (gt2d, gt3d)), ("2D tracker", RAW, (box2d_raw,)),
                                                       ("reported", FUSED, (box2d,)), ("3D box", BOX3D, (box3d,)))
           if any(_drawn(b) for b in boxes)]
    x, y = 6, img.shape[0] - 8
    for name, colour in key:
        cv2.putText(img, name, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1, cv2.LINE_AA)
        x += cv2.getTextSize(name, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)[0][0] + 12
    return img


class OverlayWriter:
    """Collects overlay frames into `path`: .gif (pillow, frames downscaled to max_width) or .mp4.

    A .gif path falls back to .mp4 when pillow is missing; ``path`` tells the file written.
    """

    def __init__(self, path: str | Path, fps: float = 10.0, max_width: int = 480, max_frames: int = 300):
        self.path = Path(path)
        self.fps = float(fps)
        self.max_width = int(max_width)
        self.max_frames = int(max_frames)
        self._frames: list[np.ndarray] = []
        self._video = None
        if self.path.suffix.lower() == ".gif":
            try:
                import PIL.Image  # noqa: F401  (only to know whether GIF writing is possible)
            except ImportError:
                import warnings

                warnings.warn(f"no pillow for GIF overlays: writing {self.path.with_suffix('.mp4').name} "
                              "instead (pip install 'track3d[plot]')", RuntimeWarning, stacklevel=2)
                self.path = self.path.with_suffix(".mp4")
        elif self.path.suffix.lower() != ".mp4":
            raise ValueError(f"overlay files are .gif or .mp4, got {self.path.name}")
        self.path.parent.mkdir(parents=True, exist_ok=True)

    def _scaled(self, frame: np.ndarray) -> np.ndarray:
        h, w = frame.shape[:2]
        if w <= self.max_width:
            return frame
        s = self.max_width / w
        return cv2.resize(frame, (self.max_width, max(1, int(round(h * s)))), interpolation=cv2.INTER_AREA)

    def add(self, frame: np.ndarray) -> None:
        f = self._scaled(frame)
        if self.path.suffix == ".gif":
            if len(self._frames) < self.max_frames:
                self._frames.append(f)
            return
        if self._video is None:
            self._video = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), self.fps,
                                          (f.shape[1], f.shape[0]))
        self._video.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))

    def close(self) -> Path:
        if self.path.suffix == ".gif" and self._frames:
            from PIL import Image

            imgs = [Image.fromarray(f) for f in self._frames]
            imgs[0].save(self.path, save_all=True, append_images=imgs[1:], duration=int(1000 / self.fps),
                         loop=0, optimize=False)
            self._frames = []
        if self._video is not None:
            self._video.release()
            self._video = None
        return self.path
