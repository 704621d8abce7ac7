"""Frustum proposal (paper section IV-A) and the random point sampling A3BoxNet needs.

Two implementations with identical results:

- the compiled extension ``track3d._frustum`` (one C++ pass over the cloud, GIL released),
  used by :func:`extract_frustum`, :func:`extract_frustum_bounds` (the same points plus their
  per-axis min / max from the same pass, which the loop's checks use) and :func:`sample_points`;
- plain numpy references, :func:`extract_frustum_numpy`, :func:`extract_frustum_bounds_numpy`
  and :func:`sample_points_numpy`,
  which define the semantics and which the tests compare the extension against.

Frustum semantics (paper IV-A): keep the points with ``z_min <= z <= z_max`` (1 .. 45 m),
project them with the 3x4 camera matrix M, ``(u, v) = (p0 / p2, p1 / p2)`` with
``p = M [x y z 1]^T``, and keep those whose projection lies in the half-open box
``x <= u < x + w`` and ``y <= v < y + h`` (pixel (i, j) covers [i, i+1) x [j, j+1), see
camera.py). Input order is preserved. Points with a NaN/inf coordinate are dropped.
An empty cloud, a zero-size or non-finite box, a box outside the image: an empty (0, 3) result.

The projection is computed in float64 in both implementations, with the same operation
order, so the two agree bit for bit on which points are kept.

Sampling semantics (:func:`sample_points`), for ``n`` input points and ``num`` wanted:

- ``n >= num``: ``num`` distinct points (without replacement), in random order;
- ``0 < n < num``: every point once, then ``num - n`` extra points drawn with replacement,
  the whole result in input order followed by the extras (so no information is lost);
- ``n == 0``: ValueError (the caller reports a 'no points' status instead).

The random generator is a fixed, documented algorithm so that results are reproducible
across platforms and identical between C++ and numpy: SplitMix64 seeded with ``seed``;
a uniform index below ``k`` is ``(next() >> 11) * k >> 53`` computed exactly (a 53-bit
fixed-point multiply, bias < 2^-53 * k). Without replacement uses a partial Fisher-Yates
shuffle of ``arange(n)``: for ``i in 0..num-1`` swap ``idx[i]`` with ``idx[i + r]``,
``r = uniform(n - i)``; the first ``num`` entries are the sample. With replacement draws
``uniform(n)`` for each extra point.
"""
from __future__ import annotations

import warnings

import numpy as np

from .frames import check_cloud, point_bounds

__all__ = [
    "Z_MIN", "Z_MAX", "extract_frustum", "extract_frustum_numpy", "frustum_mask_numpy",
    "extract_frustum_bounds", "extract_frustum_bounds_numpy", "MAX_SAMPLE",
    "sample_points", "sample_points_numpy", "sample_indices_numpy", "HAVE_EXTENSION", "lone_scan",
    "lone_mask_numpy", "LONE_MAX_CELLS",
]

Z_MIN = 1.0   # metres, paper IV-A: 1 <= z <= 45
Z_MAX = 45.0

try:  # the compiled extension; the numpy reference stands in only if it lacks a function
    from . import _frustum as _ext
except ImportError as _err:  # a wheel built for another machine (its glibc / libstdc++), a broken build
    _ext = None
    # same results, about 3x the frustum's time: say so once rather than run slow in silence
    warnings.warn(f"track3d: its compiled extension track3d._frustum did not load ({_err}); the numpy "
                  "reference runs instead: the same results, slower (reinstall track3d built for this "
                  "machine; `track3d bench` shows which runs)", RuntimeWarning, stacklevel=2)

# Per function: an older build of the extension may lack one; numpy then stands in for it.
_ext_extract = getattr(_ext, "extract_frustum", None)
_ext_sample = getattr(_ext, "sample_points", None)
_ext_bounds = getattr(_ext, "extract_frustum_bounds", None)
_ext_lone = getattr(_ext, "lone_scan", None)
HAVE_EXTENSION = _ext_extract is not None and _ext_sample is not None
# every function of this code's extension present (an older build runs some in numpy)
EXTENSION_COMPLETE = None not in (_ext_extract, _ext_sample, _ext_bounds, _ext_lone)
if _ext is not None and None in (_ext_extract, _ext_sample, _ext_bounds, _ext_lone):
    # an editable install whose C++ was not rebuilt after a pull: right, but slower
    warnings.warn("track3d: its compiled extension track3d._frustum is older than this code (it lacks "
                  + ", ".join(n for n, f in (("extract_frustum", _ext_extract), ("sample_points", _ext_sample),
                                             ("extract_frustum_bounds", _ext_bounds), ("lone_scan", _ext_lone))
                              if f is None)
                  + "); the numpy reference stands in for those: rebuild it (pip install -e . --no-deps)",
                  RuntimeWarning, stacklevel=2)

_MASK64 = (1 << 64) - 1


def _check_points(points: np.ndarray) -> np.ndarray:
    p = check_cloud(points)   # the loop's contract, one message (an empty cloud of any shape: no points)
    if callable(p):
        raise ValueError("points must be an (N, 3) array here, got a callable")
    if p.size == 0:
        return np.zeros((0, 3), np.float32)
    return np.ascontiguousarray(p, dtype=np.float32)


def _check_box(box2d: np.ndarray) -> np.ndarray:
    b = np.asarray(box2d, dtype=np.float64).reshape(-1)
    if b.shape != (4,):
        raise ValueError(f"box2d must be [x, y, w, h], got shape {np.shape(box2d)}")
    return b


def _check_matrix(M: np.ndarray) -> np.ndarray:
    m = np.ascontiguousarray(M, dtype=np.float64)
    if m.shape != (3, 4):
        raise ValueError(f"camera matrix M must have shape (3, 4), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("camera matrix M has non-finite entries")
    return m


def frustum_mask_numpy(points: np.ndarray, box2d: np.ndarray, M: np.ndarray,
                       z_min: float = Z_MIN, z_max: float = Z_MAX) -> np.ndarray:
    """(N,) bool mask of the frustum points; the numpy reference of the selection rule."""
    p = _check_points(points)
    b = _check_box(box2d)
    m = _check_matrix(M)
    if len(p) == 0 or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
        return np.zeros(len(p), dtype=bool)
    x = p[:, 0].astype(np.float64)
    y = p[:, 1].astype(np.float64)
    z = p[:, 2].astype(np.float64)
    finite = np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
    keep = finite & (z >= z_min) & (z <= z_max)
    # Same operation order as the C++ kernel: ((m0*x + m1*y) + m2*z) + m3.
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        p0 = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3]
        p1 = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3]
        p2 = m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3]
        u = p0 / p2
        v = p1 / p2
        x0, y0 = b[0], b[1]
        x1, y1 = b[0] + b[2], b[1] + b[3]
        keep &= (p2 > 0) & (u >= x0) & (u < x1) & (v >= y0) & (v < y1)
    return keep


def extract_frustum_numpy(points: np.ndarray, box2d: np.ndarray, M: np.ndarray,
                          z_min: float = Z_MIN, z_max: float = Z_MAX) -> np.ndarray:
    """Numpy reference of :func:`extract_frustum`: (N, 3) float32 -> (n, 3) float32."""
    p = _check_points(points)
    return p[frustum_mask_numpy(p, box2d, M, z_min, z_max)]


def extract_frustum(points: np.ndarray, box2d: np.ndarray, M: np.ndarray,
                    z_min: float = Z_MIN, z_max: float = Z_MAX) -> np.ndarray:
    """Frustum proposal: the points of the cloud whose projection falls in the 2D box.

    points: (N, 3) float32 in the camera frame of M (other float dtypes are converted);
    box2d: (4,) [x, y, w, h] pixels; M: (3, 4) float64 camera matrix (``Camera.M``);
    z_min, z_max: depth crop in metres. Returns (n, 3) float32, input order preserved.
    """
    p = _check_points(points)
    b = _check_box(box2d)
    m = _check_matrix(M)
    if _ext_extract is None:
        return extract_frustum_numpy(p, b, m, z_min, z_max)
    return _ext_extract(p, b, m, float(z_min), float(z_max))


def _bounds_of(p: np.ndarray) -> np.ndarray:
    if len(p) == 0:
        return np.array([[np.inf] * 3, [-np.inf] * 3])
    return np.stack(point_bounds(p)).astype(np.float64)


def extract_frustum_bounds_numpy(points: np.ndarray, box2d: np.ndarray, M: np.ndarray,
                                 z_min: float = Z_MIN, z_max: float = Z_MAX) -> tuple[np.ndarray, np.ndarray]:
    """Numpy reference of :func:`extract_frustum_bounds`."""
    kept = extract_frustum_numpy(points, box2d, M, z_min, z_max)
    return kept, _bounds_of(kept)


def extract_frustum_bounds(points: np.ndarray, box2d: np.ndarray, M: np.ndarray,
                           z_min: float = Z_MIN, z_max: float = Z_MAX) -> tuple[np.ndarray, np.ndarray]:
    """:func:`extract_frustum` plus the enclosing box of the kept points, from the same pass.

    Returns (points (n, 3) float32, bounds (2, 3) float64 ``[[min x, y, z], [max x, y, z]]``;
    ``+inf`` / ``-inf`` rows when n == 0). The kept points are finite by construction (the
    selection drops NaN / inf), so the loop needs no second pass to check or measure them.
    """
    p = _check_points(points)
    b = _check_box(box2d)
    m = _check_matrix(M)
    if _ext_bounds is None:
        return extract_frustum_bounds_numpy(p, b, m, z_min, z_max)
    return _ext_bounds(p, b, m, float(z_min), float(z_max))


# --- sampling -------------------------------------------------------------------------------

class _SplitMix64:
    """SplitMix64 (Steele, Lea, Flood 2014): the generator the C++ kernel uses too."""

    def __init__(self, seed: int):
        self.state = int(seed) & _MASK64

    def next(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & _MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
        return z ^ (z >> 31)

    def below(self, k: int) -> int:
        """Uniform integer in [0, k): 53 random bits times k, top bits (exact integer math)."""
        return ((self.next() >> 11) * k) >> 53


MAX_SAMPLE = 10_000_000   # more sampled points than any network takes: a caller error


def _check_seed(seed) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    return int(seed) & _MASK64


def _check_sampling(n: int, num) -> None:
    if isinstance(num, (bool, np.bool_)) or not isinstance(num, (int, np.integer)):
        raise ValueError(f"num must be an integer, got {num!r}")
    if not 1 <= int(num) <= MAX_SAMPLE:
        raise ValueError(f"num must be in 1..{MAX_SAMPLE}, got {num}")
    if n == 0:
        raise ValueError("cannot sample from an empty point set")


def sample_indices_numpy(n: int, num: int, seed: int) -> np.ndarray:
    """Reference of the sampling algorithm (module docstring): (num,) int64 indices into n points.

    Pure Python integer arithmetic: slow, for tests; the extension does the same in C++.
    """
    _check_sampling(n, num)
    num = int(num)
    rng = _SplitMix64(_check_seed(seed))
    if n >= num:
        idx = list(range(n))
        for i in range(num):
            j = i + rng.below(n - i)
            idx[i], idx[j] = idx[j], idx[i]
        return np.asarray(idx[:num], dtype=np.int64)
    extra = [rng.below(n) for _ in range(num - n)]
    return np.concatenate([np.arange(n, dtype=np.int64), np.asarray(extra, dtype=np.int64)])


def sample_points_numpy(points: np.ndarray, num: int, seed: int) -> np.ndarray:
    """Reference of :func:`sample_points` (same indices, same result)."""
    p = _check_points(points)
    return p[sample_indices_numpy(len(p), num, seed)]


def sample_points(points: np.ndarray, num: int, seed: int) -> np.ndarray:
    """Random sampling of a frustum to exactly ``num`` points, as A3BoxNet's input needs.

    points: (n, 3) float32, n >= 1; returns (num, 3) float32. Without replacement when
    n >= num; all points plus ``num - n`` random repeats when n < num. Deterministic for a
    seed (SplitMix64, module docstring). Raises ValueError when n == 0, or num or seed is not
    an integer, or num is outside 1..MAX_SAMPLE.
    """
    p = _check_points(points)
    _check_sampling(len(p), num)
    if _ext_sample is None:
        return sample_points_numpy(p, num, seed)
    return _ext_sample(p, int(num), _check_seed(seed))


LONE_MAX_CELLS = 1 << 24   # a grid past this many cells is no frustum's (kMaxCells in cpp_ext/frustum.cpp)


def lone_mask_numpy(points: np.ndarray, M: np.ndarray, cell: float) -> np.ndarray:
    """(N,) bool: the points with no other point in the 3 x 3 cells of `cell` pixels around their
    own, projected under M (3, 4) in float32 (M's entries rounded to float32; u = (row 0 . p) * w,
    v = (row 1 . p) * w, w = 1 / (row 2 . p), each sum left to right); all False with fewer than 2
    points, a coordinate or projection that is not finite, or a grid of more than LONE_MAX_CELLS
    cells. The reference of the C++ `lone_scan`'s mask (the same, bit for bit)."""
    p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    n = len(p)
    out = np.zeros(n, bool)
    if n < 2:
        return out
    m = np.asarray(M, dtype=np.float64).reshape(-1).astype(np.float32)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    with np.errstate(all="ignore"):
        w = np.float32(1.0) / (m[8] * x + m[9] * y + m[10] * z + m[11])
        u = (m[0] * x + m[1] * y + m[2] * z + m[3]) * w
        v = (m[4] * x + m[5] * y + m[6] * z + m[7]) * w
    if not (np.isfinite(u).all() and np.isfinite(v).all() and np.isfinite(z).all()):
        return out
    inv = np.float32(1.0) / np.float32(cell)
    fu, fv = (u - u.min()) * inv, (v - v.min()) * inv
    if not ((fu < np.float32(1e9)).all() and (fv < np.float32(1e9)).all()):
        return out
    iu, iv = fu.astype(np.int64), fv.astype(np.int64)
    nx, ny = int(iu.max()) + 1, int(iv.max()) + 1
    if not (nx <= LONE_MAX_CELLS // max(ny, 1) and nx * ny <= LONE_MAX_CELLS):
        return out
    count = np.bincount(iv * nx + iu, minlength=nx * ny).reshape(ny, nx)
    padded = np.pad(count, 1)
    near = sum(padded[r:r + ny, c:c + nx] for r in range(3) for c in range(3))
    return near[iv, iu] == 1


def lone_scan(points: np.ndarray, M: np.ndarray, cell: float, bucket: float) -> tuple[np.ndarray, bool]:
    """(lone_mask_numpy's mask, one_run) from one pass of the C++ extension (GIL released).
    one_run True says that the depths of the points not lone leave no `bucket`-wide slot empty
    between their least and greatest, so none of them in depth order lies more than 2 * bucket
    from the next; False when that was not established (always, where the extension lacks the
    function and the numpy reference stands in). points (N, 3) float32 (the frustum's)."""
    for name, val in (("cell", cell), ("bucket", bucket)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a positive number, got {val}")
    if _ext_lone is None:
        return lone_mask_numpy(points, M, cell), False
    mask, one_run = _ext_lone(np.ascontiguousarray(points, dtype=np.float32),
                              np.ascontiguousarray(M, dtype=np.float64), float(cell), float(bucket))
    return mask.view(bool), bool(one_run)
