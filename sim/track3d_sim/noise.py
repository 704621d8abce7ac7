"""Seeded, periodic band-limited noise on 2D / 3D grids and trilinear lookup.

Noise is made by filtering white Gaussian noise in the Fourier domain with a power
law (fBm-like), so a grid is periodic (a tile has no seams) and cheap (one FFT).
Solid (3D) textures are sampled with trilinear interpolation at body-frame points,
so asteroid textures need no UV map and have no seams.
"""
from __future__ import annotations

import numpy as np


def fft_noise(rng: np.random.Generator, shape: tuple[int, ...], beta: float = 2.0,
              fmin: float = 1.0, fmax: float | None = None) -> np.ndarray:
    """Periodic noise of the given shape with power spectrum ~ 1/f^beta between fmin and fmax
    (cycles per grid period), normalised to zero mean, unit std (float32)."""
    white = rng.standard_normal(shape)
    spec = np.fft.rfftn(white)
    freqs = np.meshgrid(*[np.fft.fftfreq(n) * n for n in shape[:-1]], np.fft.rfftfreq(shape[-1]) * shape[-1],
                        indexing="ij")
    f = np.sqrt(sum(g * g for g in freqs))
    amp = np.where(f >= fmin, np.power(np.maximum(f, 1e-6), -beta / 2.0), 0.0)
    if fmax is not None:
        amp = np.where(f <= fmax, amp, 0.0)
    out = np.fft.irfftn(spec * amp, s=shape, axes=tuple(range(len(shape))))
    out -= out.mean()
    sd = out.std()
    return (out / (sd if sd > 0 else 1.0)).astype(np.float32)


def trilinear(grid: np.ndarray, coords: np.ndarray, wrap: bool = True) -> np.ndarray:
    """Sample grid (n0, n1, n2[, C]) at continuous coords (M, 3) in grid units.

    wrap=True: periodic; else coordinates are clamped to the grid."""
    n = np.array(grid.shape[:3])
    C = grid.shape[3] if grid.ndim == 4 else 1
    flat = grid.reshape(-1, C)
    c = np.asarray(coords, dtype=np.float64)
    if not wrap:
        c = np.clip(c, 0.0, n - 1.000001)
    i0 = np.floor(c).astype(np.int64)
    f = (c - i0).astype(np.float32)
    if wrap:
        i0 %= n
        i1 = (i0 + 1) % n
    else:
        i1 = np.minimum(i0 + 1, n - 1)
    sx, sy = n[1] * n[2], n[2]
    ax = (i0[:, 0] * sx, i1[:, 0] * sx)
    ay = (i0[:, 1] * sy, i1[:, 1] * sy)
    az = (i0[:, 2], i1[:, 2])
    wx = (1.0 - f[:, 0], f[:, 0])
    wy = (1.0 - f[:, 1], f[:, 1])
    wz = (1.0 - f[:, 2], f[:, 2])
    chans = [np.ascontiguousarray(flat[:, k]) for k in range(C)]  # 1D gathers are much faster
    out = np.zeros((C, len(c)), np.float32)
    for dx in (0, 1):
        for dy in (0, 1):
            base = ax[dx] + ay[dy]
            wxy = wx[dx] * wy[dy]
            for dz in (0, 1):
                idx = base + az[dz]
                w = wxy * wz[dz]
                for k in range(C):
                    out[k] += chans[k].take(idx) * w
    return out.T if grid.ndim == 4 else out[0]
