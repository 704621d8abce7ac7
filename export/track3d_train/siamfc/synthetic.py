"""Synthetic asteroid-like sequences: a lit, textured blob moving over a star field.

Used by the tests (the runtime tracker must follow it) and for a short pre-training before the
simulator's train split (the paper pre-trains on ILSVRC-VID, which we do not have here).
Deterministic for a given numpy Generator.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["star_field", "blob_sprite", "synthetic_sequence"]


def star_field(h: int, w: int, rng: np.random.Generator, density: float = 0.002) -> np.ndarray:
    img = np.zeros((h, w, 3), np.float32)
    n = int(h * w * density)
    ys, xs = rng.integers(0, h, n), rng.integers(0, w, n)
    img[ys, xs] = rng.uniform(40, 255, (n, 1)) * rng.uniform(0.8, 1.0, (n, 3))
    img = cv2.GaussianBlur(img, (3, 3), 0.6)
    img += rng.uniform(0, 6)  # faint background glow
    return img


def blob_sprite(size: int, rng: np.random.Generator, light: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A (size, size, 3) float sprite of an irregular lit body and its (size, size) alpha mask."""
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    c = (size - 1) / 2.0
    ang = np.arctan2(yy - c, xx - c)
    r = np.hypot(yy - c, xx - c) / (size / 2.0)
    k = rng.integers(2, 6)
    edge = 0.85 + sum(rng.uniform(-0.08, 0.08) * np.cos(j * ang + rng.uniform(0, 6.28)) for j in range(1, k + 1))
    mask = (r <= edge).astype(np.float32)
    # texture: multi-scale noise + craters
    tex = np.zeros((size, size), np.float32)
    for s in (4, 8, 16):
        g = rng.uniform(0, 1, (max(2, size // s), max(2, size // s))).astype(np.float32)
        tex += cv2.resize(g, (size, size), interpolation=cv2.INTER_CUBIC) / 3.0
    for _ in range(rng.integers(3, 9)):
        cx, cy, rr = rng.uniform(0, size), rng.uniform(0, size), rng.uniform(size * 0.04, size * 0.15)
        cv2.circle(tex, (int(cx), int(cy)), int(rr), float(rng.uniform(0.1, 0.4)), -1)
    # Lambert-ish shading from a light direction
    if light is None:
        light = rng.normal(size=3)
        light[2] = abs(light[2]) + 0.3
    light = light / np.linalg.norm(light)
    rn = np.clip(r / np.maximum(edge, 1e-3), 0, 0.999)
    nz = np.sqrt(1 - rn ** 2)
    nx, ny = (xx - c) / (size / 2.0), (yy - c) / (size / 2.0)
    shade = np.clip(nx * light[0] + ny * light[1] + nz * light[2], 0.03, 1)
    albedo = rng.uniform(60, 200)
    tint = rng.uniform(0.8, 1.0, 3)
    gray = albedo * shade * (0.5 + 0.7 * tex)
    sprite = gray[..., None] * tint[None, None, :]
    mask = cv2.GaussianBlur(mask, (3, 3), 0.7)
    return sprite.astype(np.float32), mask


def synthetic_sequence(n_frames: int = 40, h: int = 240, w: int = 320, rng: np.random.Generator | None = None,
                       size_range: tuple = (30, 70), speed: float = 3.0, noise: float = 2.0):
    """Frames (n, h, w, 3) uint8 RGB and boxes (n, 4) [x, y, w, h] of a moving, slowly scaling blob."""
    rng = rng or np.random.default_rng(0)
    bg = star_field(h, w, rng)
    base = int(rng.integers(size_range[0], size_range[1] + 1))
    sprite, mask = blob_sprite(base * 2, rng)  # render big, shrink per frame
    ys, xs = np.nonzero(mask > 0.5)
    tight = np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], np.float64) / 2.0  # at scale 1
    pos = np.array([rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h])
    vel = rng.normal(size=2)
    vel = vel / (np.linalg.norm(vel) + 1e-9) * speed
    scale, dscale = 1.0, rng.uniform(-0.004, 0.006)
    frames = np.empty((n_frames, h, w, 3), np.uint8)
    boxes = np.empty((n_frames, 4), np.float64)
    for t in range(n_frames):
        s = base * scale / (base * 2)  # sprite pixels -> image pixels
        m = np.array([[s, 0, pos[0] - s * base], [0, s, pos[1] - s * base]], np.float64)
        spr = cv2.warpAffine(sprite, m, (w, h), flags=cv2.INTER_LINEAR)
        msk = cv2.warpAffine(mask, m, (w, h), flags=cv2.INTER_LINEAR)[..., None]
        img = bg * (1 - msk) + spr * msk
        img += rng.normal(0, noise, img.shape).astype(np.float32)
        frames[t] = np.clip(img, 0, 255).astype(np.uint8)
        # tight box of the mask at this pose (sprite coordinates mapped by m)
        bx0, by0 = m[0, 0] * tight[0] * 2 + m[0, 2], m[1, 1] * tight[1] * 2 + m[1, 2]
        bx1, by1 = m[0, 0] * tight[2] * 2 + m[0, 2], m[1, 1] * tight[3] * 2 + m[1, 2]
        boxes[t] = [bx0, by0, bx1 - bx0, by1 - by0]
        # motion: smooth random walk that stays inside the frame
        vel = 0.9 * vel + rng.normal(0, 0.5, 2)
        vel = vel / (np.linalg.norm(vel) + 1e-9) * speed
        pos = pos + vel
        margin = base * scale * 0.6
        for k, lim in ((0, w), (1, h)):
            if pos[k] < margin or pos[k] > lim - margin:
                vel[k] = -vel[k]
                pos[k] = np.clip(pos[k], margin, lim - margin)
        scale = float(np.clip(scale * (1 + dscale), 0.6, 1.6))
    return frames, boxes
