"""Nine space backgrounds, synthesised in 2D (cheap) and seeded.

Everything in a background is at infinity: it has no depth, and the left and right
images see it at the same pixels. A background is drawn once per sequence on a canvas
a little larger than the image and cropped with a slow drift (the observer's slow
attitude motion), so stars move a little across a sequence. Values are linear image
values in DN (0..255 scale) before sensor noise.
"""
from __future__ import annotations

import numpy as np

from .noise import fft_noise

SCENES = ("deep_black", "sparse_stars", "dense_stars", "galaxy_band", "planet_limb",
          "stray_light", "nebula", "distant_moon", "sun_glare")

STAR_TINTS = np.array([[1.0, 0.85, 0.7], [1.0, 0.95, 0.9], [1.0, 1.0, 1.0], [0.85, 0.9, 1.0], [0.75, 0.85, 1.0]])


def _stars(rng, img, n, bright=60.0, alpha=1.8):
    H, W, _ = img.shape
    if n <= 0:
        return
    x = rng.uniform(0, W, n)
    y = rng.uniform(0, H, n)
    # power law flux: many faint, few bright
    flux = bright * (1.0 - rng.random(n)) ** (-1.0 / alpha) * 1.5
    flux = np.minimum(flux, 4000.0)
    tint = STAR_TINTS[rng.integers(0, len(STAR_TINTS), n)]
    sig = 0.6
    ix = np.floor(x).astype(int)
    iy = np.floor(y).astype(int)
    fx, fy = x - ix - 0.5, y - iy - 0.5
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            w = np.exp(-((dx - fx) ** 2 + (dy - fy) ** 2) / (2 * sig * sig)) / (2 * np.pi * sig * sig)
            xx, yy = ix + dx, iy + dy
            ok = (xx >= 0) & (xx < W) & (yy >= 0) & (yy < H)
            np.add.at(img, (yy[ok], xx[ok]), (flux[ok] * w[ok])[:, None] * tint[ok])


def _smooth2d(rng, H, W, beta=3.0, fmin=1.0):
    n = int(2 ** np.ceil(np.log2(max(H, W))))
    return fft_noise(rng, (n, n), beta=beta, fmin=fmin)[:H, :W]


def make_background(index: int, rng: np.random.Generator, H: int, W: int) -> np.ndarray:
    """(H, W, 3) float32 background in DN for scene `index`."""
    img = np.zeros((H, W, 3), np.float32)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    area = H * W / (640 * 480)
    k = int(index)
    if k == 0:      # deep black: a handful of faint stars
        _stars(rng, img, int(20 * area), bright=15)
    elif k == 1:    # sparse stars
        _stars(rng, img, int(250 * area), bright=30)
    elif k == 2:    # dense star field
        _stars(rng, img, int(2500 * area), bright=20)
    elif k == 3:    # galaxy band: diffuse glow + star concentration along a line
        ang = rng.uniform(0, np.pi)
        nx, ny = -np.sin(ang), np.cos(ang)
        c = rng.uniform(0.3, 0.7, 2) * (W, H)
        dist = (xx - c[0]) * nx + (yy - c[1]) * ny
        width = rng.uniform(0.08, 0.18) * max(H, W)
        glow = np.exp(-0.5 * (dist / width) ** 2)
        cloud = np.clip(1.0 + 0.6 * _smooth2d(rng, H, W, 2.5, 2.0), 0, None)
        dust = np.clip(1.0 - 0.5 * np.clip(_smooth2d(rng, H, W, 3.0, 3.0), 0, None), 0.2, 1)
        img += (14.0 * glow * cloud * dust)[..., None] * np.array([1.0, 0.93, 0.82], np.float32)
        _stars(rng, img, int(600 * area), bright=18)
        n_band = int(3000 * area)
        t = rng.uniform(-1.5, 1.5, n_band) * max(H, W)
        off = rng.normal(0, width * 0.6, n_band)
        px = c[0] + t * np.cos(ang) + off * nx
        py = c[1] + t * np.sin(ang) + off * ny
        band = np.zeros_like(img)
        _stars(np.random.default_rng(rng.integers(2**31)), band, 0)
        ok = (px >= 0) & (px < W - 1) & (py >= 0) & (py < H - 1)
        fl = 6.0 * (1 - rng.random(ok.sum())) ** (-1 / 2.2)
        np.add.at(img, (py[ok].astype(int), px[ok].astype(int)), np.minimum(fl, 200)[:, None] * np.ones(3))
    elif k == 4:    # planet limb: a large lit disc entering from one side, with a thin atmosphere
        side = rng.integers(4)
        R = rng.uniform(1.2, 3.0) * max(H, W)
        depth_in = rng.uniform(0.12, 0.35) * (H if side in (0, 1) else W)
        if side == 0:
            cx, cy = rng.uniform(0, W), H + R - depth_in
        elif side == 1:
            cx, cy = rng.uniform(0, W), -R + depth_in
        elif side == 2:
            cx, cy = W + R - depth_in, rng.uniform(0, H)
        else:
            cx, cy = -R + depth_in, rng.uniform(0, H)
        r = np.sqrt((xx - cx) ** 2 + (yy - cy) ** 2)
        inside = r < R
        sun = rng.standard_normal(2)
        sun /= np.linalg.norm(sun)
        lit = np.clip(0.35 + 0.65 * (((xx - cx) * sun[0] + (yy - cy) * sun[1]) / R), 0.0, 1.0)
        surf = np.clip(1 + 0.2 * _smooth2d(rng, H, W, 3.0, 2.0), 0.3, 2)
        col = np.array([0.55, 0.65, 0.85], np.float32) if rng.random() < 0.5 else np.array([0.85, 0.7, 0.5], np.float32)
        bright = rng.uniform(40, 110)
        img += (inside * lit * surf * bright)[..., None] * col
        atm = np.exp(-np.abs(r - R) / (0.012 * R)) * (r >= R - 2)
        img += (atm * 0.5 * bright * np.clip(lit + 0.2, 0, 1))[..., None] * np.array([0.5, 0.7, 1.0], np.float32)
        stars = np.zeros_like(img)
        _stars(rng, stars, int(150 * area), bright=20)
        img += stars * (~inside)[..., None]
    elif k == 5:    # stray light: a smooth glow from one corner plus faint stars
        cx, cy = rng.choice([-0.2, 1.2]) * W, rng.uniform(-0.2, 1.2) * H
        d = np.sqrt((xx - cx) ** 2 + (yy - cy) ** 2) / max(H, W)
        img += (rng.uniform(20, 50) * np.exp(-d / rng.uniform(0.2, 0.45)))[..., None] * np.array([1.0, 0.95, 0.85], np.float32)
        _stars(rng, img, int(120 * area), bright=25)
    elif k == 6:    # nebula: coloured diffuse clouds and stars
        for col in (np.array([0.9, 0.3, 0.4]), np.array([0.3, 0.5, 1.0]), np.array([0.4, 0.9, 0.6])):
            cl = np.clip(_smooth2d(rng, H, W, 3.0, 1.0) - 0.3, 0, None) ** 1.5
            img += (8.0 * cl)[..., None] * col.astype(np.float32)
        _stars(rng, img, int(900 * area), bright=22)
    elif k == 7:    # distant moon: a small bright cratered disc and stars
        R = rng.uniform(0.03, 0.08) * max(H, W)
        cx, cy = rng.uniform(0.1, 0.9) * W, rng.uniform(0.1, 0.9) * H
        r = np.sqrt((xx - cx) ** 2 + (yy - cy) ** 2)
        sun = rng.standard_normal(2)
        sun /= np.linalg.norm(sun)
        zz = np.sqrt(np.clip(1 - (r / R) ** 2, 0, 1))
        shade = np.clip(((xx - cx) * sun[0] + (yy - cy) * sun[1]) / R * 0.8 + zz * 0.6, 0, 1)
        tex = np.clip(1 + 0.3 * _smooth2d(rng, H, W, 2.0, 8.0), 0.3, 1.6)
        disc = np.clip(R + 0.5 - r, 0, 1)
        img += (disc * shade * tex * rng.uniform(80, 160))[..., None] * np.array([0.95, 0.92, 0.88], np.float32)
        _stars(rng, img, int(300 * area), bright=20)
    elif k == 8:    # sun glare: strong veiling glare from outside the field plus ghost reflections
        ang = rng.uniform(0, 2 * np.pi)
        cx, cy = W / 2 + np.cos(ang) * 0.8 * W, H / 2 + np.sin(ang) * 0.8 * H
        d = np.sqrt((xx - cx) ** 2 + (yy - cy) ** 2) / max(H, W)
        img += (rng.uniform(40, 90) / (1 + (d / 0.15) ** 2))[..., None] * np.array([1.0, 0.97, 0.9], np.float32)
        for g in range(int(rng.integers(2, 5))):  # ghosts along the line through the centre
            t = rng.uniform(0.2, 1.6)
            gx, gy = cx + (W / 2 - cx) * t, cy + (H / 2 - cy) * t
            gr = rng.uniform(0.02, 0.08) * max(H, W)
            ring = np.exp(-0.5 * ((np.sqrt((xx - gx) ** 2 + (yy - gy) ** 2) - gr) / (0.15 * gr)) ** 2)
            img += (rng.uniform(3, 10) * ring)[..., None] * np.array([0.6, 0.9, 1.0], np.float32)
        _stars(rng, img, int(60 * area), bright=25)
    else:
        raise ValueError(f"unknown scene {index}")
    return img
