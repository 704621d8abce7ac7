"""The trackers' bilinear crop with its arithmetic fixed here, not by the installed OpenCV.

The 2D trackers cut every template and search crop with one bilinear warp of the frame under an
axis-aligned map (a scale and an offset per axis: no rotation). OpenCV's `warpAffine` computes
that map in float32 and its rounding changed between releases (4.10 -> 5.0 up to 7 DN on noise,
5.0 -> 5.1 by 1 DN on about 1 value in 10,000) and differs between its CPU variants, so the same
frames gave a different box after an OpenCV upgrade; the current models and results were
measured with 5.0.0.93. This module fixes the arithmetic of that release as it runs on x86-64
CPUs with AVX2 (the wheel's AVX2 variant, also used on AVX-512 CPUs), operation by operation,
so crops are the same bytes whatever OpenCV is installed and on any CPU:

- the map is inverted in float64 (D = 1 / (sx * sy), then sy * D, sx * D and -a * t), and the
  inverse's coefficients rounded to float32;
- source column of output column x: fma(a_x, x, b_x) for the columns in whole blocks of 16 from
  the left, (a_x * x) + b_x with two roundings for the last (width mod 16) columns (the SIMD
  body and the scalar tail of that build); source row of output row y: (a_y * y) + b_y;
- s clipped to +-2^30 (where float32 has no fraction left), i = floor(s), w = s - i (float32);
  each row of the 2 x 2 neighbourhood t = fma(w_x, p1 - p0, p0), then v = fma(w_y, t1 - t0, t0),
  every operation in float32 (fma rounds once);
- v rounded half to even and clamped to 0..255;
- a neighbour outside the image is the border colour (each channel rounded half to even and
  clamped) or, for `border="replicate"`, the nearest edge pixel.

`warp_axis_aligned` is the compiled kernel (track3d._resample); `warp_axis_aligned_numpy` is the
reference it matches bit for bit (tests/test_resample.py, with OpenCV 5.0.0.93's own outputs
committed as a fixture).
"""
from __future__ import annotations

import warnings

import numpy as np

__all__ = ["warp_axis_aligned", "warp_axis_aligned_numpy", "warp_affine_gray_numpy", "inverse_map", "fma32",
           "HAVE_EXTENSION"]

try:  # the compiled kernel; the numpy reference stands in only where it is missing
    from . import _resample as _ext
except ImportError as _err:  # a wheel built for another machine (its glibc / libstdc++), a broken build
    _ext = None
    warnings.warn(f"track3d: its compiled extension track3d._resample did not load ({_err}); the numpy "
                  "reference runs instead: the same results, slower (reinstall track3d built for this "
                  "machine; `track3d bench` shows which runs)", RuntimeWarning, stacklevel=2)
HAVE_EXTENSION = _ext is not None

# the width of the SIMD body of the build whose arithmetic is fixed here (2 x 8 float32 lanes)
BLOCK = 16
_BORDERS = ("constant", "replicate")


def inverse_map(scale: tuple[float, float], offset: tuple[float, float]) -> np.ndarray:
    """float32 [a_x, b_x, a_y, b_y] of the output -> source map of the forward map
    x_out = scale[0] * x_src + offset[0], y_out = scale[1] * y_src + offset[1] (pixel centres)."""
    sx, sy = float(scale[0]), float(scale[1])
    tx, ty = float(offset[0]), float(offset[1])
    if not (np.isfinite([sx, sy, tx, ty]).all() and sx > 0.0 and sy > 0.0):
        raise ValueError(f"the crop's map must have finite offsets and positive finite scales, got "
                         f"scale {scale}, offset {offset}")
    d = sx * sy
    d = 1.0 / d if d != 0.0 else 0.0
    ax, ay = sy * d, sx * d
    with np.errstate(over="ignore"):
        m = np.array([ax, -ax * tx, ay, -ay * ty], np.float64).astype(np.float32)
    if not (np.isfinite(m).all() and m[0] > 0 and m[2] > 0):
        # a scale so small or large, or an offset so far, that float32 cannot hold the inverse
        raise ValueError(f"the crop's map is degenerate in float32 (scale {scale}, offset {offset})")
    return m


def _check(image: np.ndarray, out_size: tuple[int, int], border_value, border: str):
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"the crop needs an (H, W, 3) uint8 image, got {img.dtype} {img.shape}")
    w, h = int(out_size[0]), int(out_size[1])
    if w < 1 or h < 1:
        raise ValueError(f"the crop's size must be at least 1 x 1, got {out_size}")
    if border not in _BORDERS:
        raise ValueError(f"border must be one of {_BORDERS}, got {border!r}")
    bv = np.asarray(tuple(border_value)[:3], np.float64)
    if bv.shape != (3,) or not np.isfinite(bv).all():
        raise ValueError(f"the border colour must be three finite numbers, got {border_value}")
    return np.ascontiguousarray(img), w, h, np.clip(np.rint(bv), 0, 255).astype(np.uint8)


def fma32(a, b, c) -> np.ndarray:
    """float32 a * b + c rounded once (IEEE fma): the product is exact in float64, the sum is
    rounded to odd there (TwoSum tells when it was inexact), and rounding that to float32 is then
    the correctly rounded result (53 >= 24 + 2 bits)."""
    p = np.asarray(a, np.float32).astype(np.float64) * np.asarray(b, np.float32).astype(np.float64)
    c64 = np.asarray(c, np.float32).astype(np.float64)
    p, c64 = np.broadcast_arrays(p, c64)
    shape = p.shape
    p, c64 = p.reshape(-1), c64.reshape(-1)
    s = p + c64
    bb = s - p
    err = (p - (s - bb)) + (c64 - bb)
    fix = (err != 0.0) & ((s.view(np.int64) & 1) == 0)
    if fix.any():
        s[fix] = np.nextafter(s[fix], np.where(err[fix] > 0.0, np.inf, -np.inf))
    return s.astype(np.float32).reshape(shape)


def _bilinear(src: np.ndarray, a: np.ndarray, w: int, h: int, fill) -> np.ndarray:
    """(h, w, C) float32 bilinear samples of an (H, W, C) float32 image at the float32 inverse
    map a = [a0, a1, a2, a3, a4, a5] (x_src = a0 x + a1 y + a2, y_src = a3 x + a4 y + a5, in the
    module's arithmetic); outside the image `fill` ((C,) float32) or, for None, the nearest edge
    pixel. The one implementation behind both references."""
    H, W = src.shape[:2]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    body = xs < np.float32((w // BLOCK) * BLOCK)

    def coord(c0, c1, c2):
        row = (ys * c1).astype(np.float32)
        s_body = fma32(c0, xs, (row + c2).astype(np.float32))   # the SIMD body: the row term first
        s_tail = (fma32(xs, c0, row) + c2).astype(np.float32)   # the scalar tail, as compiled
        # beyond 2^30 a float32 has no fraction and the index only needs to stay outside the
        # image: clipping there changes no crop and keeps an overflow to inf from the int cast
        s = np.clip(np.where(body, s_body, s_tail), np.float32(-(2.0 ** 30)), np.float32(2.0 ** 30))
        f = np.floor(s)
        return f.astype(np.int64), (s - f).astype(np.float32)[..., None]

    ix, fx = coord(a[0], a[1], a[2])
    iy, fy = coord(a[3], a[4], a[5])

    def px(r, c):
        v = src[np.clip(r, 0, H - 1), np.clip(c, 0, W - 1)]
        if fill is None:
            return v
        ok = (r >= 0) & (r < H) & (c >= 0) & (c < W)
        return np.where(ok[..., None], v, fill).astype(np.float32)

    t0 = fma32(fx, (px(iy, ix + 1) - px(iy, ix)).astype(np.float32), px(iy, ix))
    t1 = fma32(fx, (px(iy + 1, ix + 1) - px(iy + 1, ix)).astype(np.float32), px(iy + 1, ix))
    return fma32(fy, (t1 - t0).astype(np.float32), t0)


def warp_axis_aligned_numpy(image: np.ndarray, scale: tuple[float, float], offset: tuple[float, float],
                            out_size: tuple[int, int], border_value=(0.0, 0.0, 0.0),
                            border: str = "constant") -> np.ndarray:
    """(out_size[1], out_size[0], 3) uint8 bilinear crop of an (H, W, 3) uint8 image under
    x_out = scale * x_src + offset per axis (pixel centres at integers); the module docstring
    gives the arithmetic. Reference of `warp_axis_aligned`."""
    img, w, h, bval = _check(image, out_size, border_value, border)
    ax, bx, ay, by = inverse_map(scale, offset)
    a = np.array([ax, 0.0, bx, 0.0, ay, by], np.float32)
    fill = None if border == "replicate" else bval.astype(np.float32)
    v = _bilinear(img.astype(np.float32), a, w, h, fill)
    return np.clip(np.rint(v), 0, 255).astype(np.uint8)


def warp_affine_gray_numpy(image: np.ndarray, m: np.ndarray, out_size: tuple[int, int]) -> np.ndarray:
    """(out_size[1], out_size[0]) float32 bilinear warp of an (H, W) float32 image under any 2 x 3
    affine map m (source -> output, as cv2.warpAffine's), zero outside the image, in the module's
    arithmetic with the rotation terms kept (the row term (a1 * y) + a2; the tail columns
    fma(x, a0, a1 * y) + a2): that of OpenCV 5.0.0.93's AVX2 variant for one float32 channel. For
    the training's small kernels (the motion blur's rotated line), which must not change with the
    installed OpenCV."""
    img = np.asarray(image, np.float32)
    if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"the warp needs an (H, W) float32 image, got {img.shape}")
    w, h = int(out_size[0]), int(out_size[1])
    if w < 1 or h < 1:
        raise ValueError(f"the warp's size must be at least 1 x 1, got {out_size}")
    M = np.asarray(m, np.float64).reshape(2, 3)
    d = M[0, 0] * M[1, 1] - M[0, 1] * M[1, 0]
    if not (np.isfinite(M).all() and d != 0.0):
        raise ValueError(f"the warp's map must be finite and invertible: {M.tolist()}")
    d = 1.0 / d
    a11, a22, a12, a21 = M[1, 1] * d, M[0, 0] * d, -M[0, 1] * d, -M[1, 0] * d
    inv = np.array([a11, a12, -a11 * M[0, 2] - a12 * M[1, 2], a21, a22, -a21 * M[0, 2] - a22 * M[1, 2]])
    with np.errstate(over="ignore"):
        a = inv.astype(np.float32)
    if not np.isfinite(a).all():
        raise ValueError(f"the warp's map has no finite float32 inverse: {M.tolist()}")
    return _bilinear(img[..., None], a, w, h, np.zeros(1, np.float32))[..., 0]


def warp_axis_aligned(image: np.ndarray, scale: tuple[float, float], offset: tuple[float, float],
                      out_size: tuple[int, int], border_value=(0.0, 0.0, 0.0),
                      border: str = "constant") -> np.ndarray:
    """As `warp_axis_aligned_numpy`, compiled: the same bytes; on the trackers' search crops as fast
    as OpenCV's warp or faster (`benchmarks/bench_crop.py`)."""
    if _ext is None:  # pragma: no cover
        return warp_axis_aligned_numpy(image, scale, offset, out_size, border_value, border)
    img, w, h, bval = _check(image, out_size, border_value, border)
    m = inverse_map(scale, offset)
    return _ext.warp_axis_aligned(img, m, w, h, bval, border == "replicate")
