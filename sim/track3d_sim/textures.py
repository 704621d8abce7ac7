"""Six solid (3D) albedo textures: no UV map, hence no seams.

A texture is an RGB albedo grid over the body's bounding cube (sampled trilinearly at
body-frame hit points) times a periodic fine-grain tile (repeated every
`FINE_PERIOD_M` metres, also trilinear). Values are relative albedos in [0, 1]; the
exposure model (render.py) maps them to image values.
"""
from __future__ import annotations

import numpy as np

from .noise import fft_noise, trilinear

TEXTURES = ("regolith", "basaltic", "layered", "mottled", "veined", "rusty_spotted")
GRID = 72
FINE = 32
FINE_PERIOD_M = 0.6


def _sig(x):
    return 1.0 / (1.0 + np.exp(-x))


class SolidTexture:
    def __init__(self, index: int, rng: np.random.Generator, vertices: np.ndarray):
        self.index = int(index)
        self.name = TEXTURES[self.index]
        lo, hi = vertices.min(0), vertices.max(0)
        side = float((hi - lo).max()) * 1.05 + 1e-6
        self.origin = (lo + hi) / 2.0 - side / 2.0
        self.voxel = side / (GRID - 1)
        n = GRID
        ax = np.linspace(-1.0, 1.0, n, dtype=np.float32)
        X, Y, Z = np.meshgrid(ax, ax, ax, indexing="ij")
        A = fft_noise(rng, (n, n, n), beta=3.5, fmin=1.0)
        B = fft_noise(rng, (n, n, n), beta=2.0, fmin=2.0)
        tint = 1.0 + rng.normal(0.0, 0.03, 3)
        k = self.index
        if k == 0:  # regolith: grey-brown fBm
            base = np.array([0.56, 0.51, 0.46])
            alb = base * (1.0 + 0.18 * A + 0.10 * B)[..., None]
            self.fine_amp = 0.30
        elif k == 1:  # basaltic: dark grey with bright clasts
            base = np.array([0.36, 0.36, 0.38])
            s = _sig((B - 1.7) * 6.0)[..., None]
            alb = base * (1.0 + 0.12 * A)[..., None] * (1 - s) + np.array([0.92, 0.9, 0.86]) * s
            self.fine_amp = 0.22
        elif k == 2:  # layered: bands along a random axis, warped
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            freq = rng.uniform(3.0, 6.0)
            s = (X * axis[0] + Y * axis[1] + Z * axis[2]) * freq + 0.35 * A
            band = 0.5 + 0.5 * np.sin(2 * np.pi * s)
            c1, c2 = np.array([0.66, 0.58, 0.47]), np.array([0.38, 0.37, 0.37])
            alb = c1 * band[..., None] + c2 * (1 - band[..., None])
            alb = alb * (1.0 + 0.08 * B)[..., None]
            self.fine_amp = 0.2
        elif k == 3:  # mottled: large bright / dark space-weathering patches
            t = _sig(2.5 * A)[..., None]
            alb = np.array([0.72, 0.68, 0.62]) * t + np.array([0.28, 0.28, 0.30]) * (1 - t)
            alb = alb * (1.0 + 0.08 * B)[..., None]
            self.fine_amp = 0.18
        elif k == 4:  # veined: thin bright veins (ridged noise) on medium grey
            v = np.exp(-(B / 0.22) ** 2)[..., None]
            alb = np.array([0.45, 0.44, 0.42]) * (1.0 + 0.1 * A)[..., None] * (1 - v) + np.array([0.9, 0.86, 0.78]) * v
            self.fine_amp = 0.2
        else:  # rusty spotted: reddish-brown with dark spots
            sp = _sig((-B - 1.4) * 5.0)[..., None]
            alb = np.array([0.62, 0.46, 0.34]) * (1.0 + 0.15 * A)[..., None] * (1 - sp) + np.array([0.14, 0.12, 0.11]) * sp
            self.fine_amp = 0.25
        self.grid = np.clip(alb * tint, 0.02, 1.0).astype(np.float32)
        self.fine = fft_noise(rng, (FINE, FINE, FINE), beta=1.6, fmin=1.0)

    def albedo(self, p_body: np.ndarray) -> np.ndarray:
        """(M, 3) body-frame points -> (M, 3) float32 RGB relative albedo."""
        if len(p_body) == 0:
            return np.zeros((0, 3), np.float32)
        c = trilinear(self.grid, (p_body - self.origin) / self.voxel, wrap=False)
        f = trilinear(self.fine, p_body * (FINE / FINE_PERIOD_M), wrap=True)
        return np.clip(c * (1.0 + self.fine_amp * np.clip(f, -2.5, 2.5))[:, None], 0.0, 1.0).astype(np.float32)
