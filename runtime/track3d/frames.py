"""The data contract shared by every tracker, estimator and the loop: an RGB image is a
(H, W, 3) uint8 array with H, W >= 1 (as_rgb makes one of a monochrome, RGBA or 16-bit camera's
frame, the one conversion rule, which the dataset reader uses too); a sensor cloud is (N, 3)
and may hold nan / inf (the frustum drops them, see track3d.frustum); the points handed to a
3D box estimator are (n, 3), n >= 1, all finite and within MAX_COORD_M of the camera; a coarse
category is an integer in -1 .. categories - 1; an initial 2D box overlaps the image and is at
most MAX_BOX_SCALE times its larger side. One check each, one message each.

The checks cost far less than the work they guard: the estimators check finiteness and range
on the enclosing box of their points (a NaN or inf coordinate makes min / max non-finite) or
on the sample they actually use, never with a separate pass over a large frustum."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

__all__ = ["check_image", "as_rgb", "to_uint8", "IMAGE_BITS", "check_cloud", "check_estimator_points", "check_point_bounds", "point_bounds", "select_points", "check_category", "check_init_box", "check_init_box3d",
           "is_integer", "MAX_COORD_M", "MAX_BOX_SCALE", "MIN_BOX_SIDE"]

MAX_COORD_M = 1e5     # metres: beyond, float32 points lose centimetres and the nets never saw such scenes
MAX_BOX_SCALE = 10.0  # an initial 2D box side above 10x the image's larger side is a caller error
# pixels: a learned tracker's state box is at least this wide and tall; a positive side of 1e-190
# underflowed the crop size (a product of two sides) to 0 and update() divided by it
MIN_BOX_SIDE = 0.01


def check_image(image, size: tuple[int, int] | None = None) -> np.ndarray:
    """Return `image` as a C-contiguous (H, W, 3) uint8 array, or raise ValueError.

    size: the expected (width, height), e.g. the camera's; a frame of another size would put
    the frustum in the wrong place, so it is refused rather than tracked.

    A camera's other formats are refused, the message naming the conversion (as_rgb): a (H, W)
    array may be a monochrome frame but also a slice or a palette's indices, and a uint16 one
    carries no bit depth, so converting here would guess; the common case costs nothing more."""
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB with H, W >= 1, got {a.shape} {a.dtype}"
                         f"{_conversion_hint(a)}")
    if size is not None and (a.shape[1], a.shape[0]) != (int(size[0]), int(size[1])):
        raise ValueError(f"image is {a.shape[1]}x{a.shape[0]} but the camera is {int(size[0])}x{int(size[1])}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


# Bit depths of a 16-bit frame's samples (a 12-bit camera writes 0..4095 in a 16-bit PNG)
IMAGE_BITS = range(8, 17)


def _conversion_hint(a: np.ndarray) -> str:
    """': <how to convert>' for an array a camera could have given (as_rgb takes it), else ''."""
    if a.ndim < 2 or a.shape[0] < 1 or a.shape[1] < 1 or (a.ndim == 3 and a.shape[2] not in (1, 2, 3, 4)) \
            or a.ndim > 3:
        return ""
    if a.dtype == np.uint16:
        return (": a 16-bit frame: track3d.frames.as_rgb(image, bits=B) with B the camera's bits "
                "(12: values 0..4095, 16: the full range)")
    if a.dtype == np.uint8:
        return ": a monochrome, grey + alpha or RGBA frame: track3d.frames.as_rgb(image)"
    if a.dtype.kind == "f":
        return ": a float frame: scale it to 0..255 and cast it to uint8"
    return ""


@lru_cache(maxsize=None)
def _table(bits: int) -> np.ndarray:
    """uint8 value of each 16-bit sample v of a `bits`-bit camera: v * 255 / (2**bits - 1), rounded
    half up in integers (exact, no float rounding): 0 -> 0, the largest value -> 255, and for
    bits = 16 a 16-bit copy of an 8-bit frame (v * 257) back to v. Samples above the largest
    value map to 255 (to_uint8 refuses them first). 64 KiB per bits."""
    top = (1 << bits) - 1
    v = np.minimum(np.arange(1 << 16, dtype=np.int64), top)
    t = ((v * 255 + top // 2) // top).astype(np.uint8)
    t.setflags(write=False)
    return t


def to_uint8(image, bits: int) -> np.ndarray:
    """A uint16 image of a `bits`-bit camera (samples 0 .. 2**bits - 1 in the low bits, as a
    12-bit camera's 0..4095 in a 16-bit PNG) as uint8 of the same shape: v * 255 / (2**bits - 1)
    rounded (_table); a uint8 image is returned as is. ValueError: another dtype, bits not an
    integer in 8..16, or a sample above 2**bits - 1 (the bits are wrong: a 16-bit camera, or one
    that writes its samples in the high bits, is bits=16).

    Why not `>> 8`: a 12-bit camera's frame would read at most 15 of 255, nearly black, and the
    trackers lose the body in it (a ToF test set: EdgeTrack's AO_2d 0.895 -> 0.699)."""
    a = np.asarray(image)
    if a.dtype == np.uint8:
        return a
    if a.dtype != np.uint16:
        raise ValueError(f"to_uint8 takes a uint16 (or uint8) image, got {a.dtype}")
    if not is_integer(bits) or int(bits) not in IMAGE_BITS:
        raise ValueError(f"bits must be an integer in {IMAGE_BITS.start}..{IMAGE_BITS.stop - 1} (the camera's "
                         f"bit depth: 12 for values 0..4095), got {bits!r}")
    bits = int(bits)
    top = a.max(initial=0)
    if top >> bits:
        raise ValueError(f"the image holds {int(top)}, above a {bits}-bit camera's {(1 << bits) - 1}: "
                         f"its bits are more (16 for the full range or samples in the high bits)")
    return _table(bits)[a]


def as_rgb(image, bits: int | None = None) -> np.ndarray:
    """A camera's frame as the contract's C-contiguous (H, W, 3) uint8 RGB (check_image), or
    ValueError. Taken: uint8 or uint16, (H, W) or (H, W, 1) monochrome (repeated into R, G, B),
    (H, W, 2) grey + alpha, (H, W, 3) RGB, (H, W, 4) RGBA (alpha dropped: a camera's alpha is no
    part of the scene). uint16 needs `bits`, the camera's bit depth (to_uint8: 12 for samples
    0..4095, 16 for the full range); a uint16 frame's bit depth cannot be told from it. Channels
    are taken in RGB order: convert OpenCV's BGR(A) first. A (H, W, 3) uint8 RGB frame is
    returned as is (no copy when C-contiguous)."""
    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"a frame is uint8 or uint16, got {a.dtype}")
    # alpha dropped before the scaling: a 12-bit frame's alpha may be 16-bit opaque (65535)
    if a.ndim == 3 and a.shape[2] in (1, 2):
        a = a[..., 0]                       # grey (+ alpha)
    elif a.ndim == 3 and a.shape[2] == 4:
        a = a[..., :3]                      # RGB (+ alpha)
    if a.dtype == np.uint16:
        if bits is None:
            raise ValueError("a 16-bit frame needs bits, the camera's bit depth (12: values 0..4095, "
                             "16: the full range)")
        a = to_uint8(a, bits)
    if a.ndim == 2:
        # OpenCV's copy into three channels: ~6x faster than np.repeat (2 vs 12 ms on 2048x1536)
        a = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_GRAY2RGB) if a.size else np.zeros(a.shape + (3,), np.uint8)
    elif a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"a frame is (H, W) or (H, W, 1 .. 4 channels), got {a.shape}")
    return check_image(a)


def check_cloud(points, needed: bool = True):
    """A frame's cloud as the loop takes it: an (N, 3) array of numbers (N >= 0, nan / inf
    allowed) returned as an ndarray, a callable box2d -> cloud returned as is, or None when not
    `needed` (a 2D-only loop); else ValueError. Checked before the loop changes any state, so a
    bad cloud leaves the tracker as it was (the 2D tracker used to have moved on already)."""
    if callable(points):
        return points
    if points is None:
        if needed:
            raise ValueError("points is None: a cloud is needed here (an (N, 3) array; no returns: (0, 3))")
        return None
    p = np.asarray(points)
    if p.dtype.kind not in "fiu":   # not bools: a mask is no cloud
        raise ValueError(f"points must be an (N, 3) array of numbers, got dtype {p.dtype}")
    # an empty cloud too: (0, 3) or (0,), not (0, 5) or (3, 0)
    if p.shape != (0,) and (p.ndim != 2 or p.shape[1] != 3):
        raise ValueError(f"points must have shape (N, 3), got {p.shape} (no returns: (0, 3))")
    return p


def check_estimator_points(points, dtype=np.float32, finite: bool = True) -> np.ndarray:
    """Return the points of a 3D box estimate as (n, 3) `dtype`, or raise ValueError: an empty
    set, another shape, or a non-finite or out-of-range coordinate (see check_point_bounds)
    would otherwise come back as a nan or absurd box.

    finite=False leaves the value check to the caller, who does it on the enclosing box or on
    the sample it uses (cheaper than a pass here)."""
    p = np.asarray(points)
    if p.dtype != dtype:
        if p.dtype.kind not in "fiub":
            raise ValueError(f"estimator points must be numbers, got dtype {p.dtype}")
        p = p.astype(dtype)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"estimator points must have shape (n, 3), got {p.shape}")
    if len(p) == 0:
        raise ValueError("a 3D box estimate needs at least one point")
    if finite:
        check_point_bounds(*point_bounds(p))
    return p


def point_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) per-axis minimum and maximum of (n, 3) points, n >= 1, in their dtype.

    Column by column: numpy's ``min(axis=0)`` over a (n, 3) array walks it 3 values at a time
    and costs ~40x more (2.3 ms vs 60 us on 46,000 points, measured)."""
    lo = np.array([points[:, k].min() for k in range(3)], dtype=points.dtype)
    hi = np.array([points[:, k].max() for k in range(3)], dtype=points.dtype)
    return lo, hi


def select_points(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``points[mask]`` for (n, 3) points and an (n,) bool mask, the same rows in the same order.

    A C-contiguous array's rows are copied as 12- (or 24-) byte records: numpy's boolean index
    of a (n, 3) array picks values one at a time and costs ~15x more (0.40 ms vs 0.025 ms on
    52,000 points, measured)."""
    p = np.asarray(points)
    if p.ndim == 2 and p.flags.c_contiguous and p.shape[1] > 0:
        rows = p.view(np.dtype((np.void, p.dtype.itemsize * p.shape[1]))).reshape(-1)
        return rows[mask].view(p.dtype).reshape(-1, p.shape[1])
    return np.compress(mask, p, axis=0)


def check_point_bounds(lo, hi) -> None:
    """Raise ValueError unless the enclosing box [lo, hi] of a point set is finite and within
    +-MAX_COORD_M (NaN / inf in any point shows up in min / max)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("estimator points must be finite (the frustum drops nan / inf; see track3d.frustum)")
    if np.any(lo < -MAX_COORD_M) or np.any(hi > MAX_COORD_M):
        raise ValueError(f"estimator points must lie within {MAX_COORD_M:g} m of the camera, "
                         f"got coordinates in [{lo.min():.3g}, {hi.max():.3g}]")


def is_integer(v) -> bool:
    """An int / numpy integer, or a float with an integer value (2.0); never a bool or a string."""
    if isinstance(v, (bool, np.bool_)):
        return False
    if isinstance(v, (int, np.integer)):
        return True
    return isinstance(v, (float, np.floating)) and float(v).is_integer()


def check_category(category, num_categories: int | None = None) -> int:
    """Return the coarse category as an int in -1 .. num_categories - 1 (-1: unknown), or raise
    ValueError; without num_categories any integer >= -1 is taken."""
    if not is_integer(category):
        raise ValueError(f"category must be an integer (-1: unknown), got {category!r}")
    c = int(category)
    if c < -1 or (num_categories is not None and c >= int(num_categories)):
        top = "" if num_categories is None else f"{int(num_categories) - 1}"
        raise ValueError(f"category must be in -1..{top or 'any'}, got {category!r}")
    return c


def check_init_box3d(box) -> np.ndarray:
    """Return a first 3D box [cx, cy, cz, sx, sy, sz] (camera frame, metres) as (6,) float64, or
    raise ValueError: not 6 finite numbers, a size not above 0, the centre not in front of the
    camera, or a coordinate beyond MAX_COORD_M."""
    try:
        b = np.asarray(box, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"a 3D box is 6 numbers [cx, cy, cz, sx, sy, sz] (metres), got {box!r:.80}") from None
    if b.shape != (6,) or not np.all(np.isfinite(b)):
        shown = str(b.tolist()) if box is not None else "None"
        raise ValueError(f"a 3D box is 6 finite numbers [cx, cy, cz, sx, sy, sz] (metres), got {shown:.120}")
    if np.any(b[3:] <= 0.0) or b[2] <= 0.0 or np.any(np.abs(b) > MAX_COORD_M):
        raise ValueError(f"a 3D box needs sizes above 0 and its centre in front of the camera (cz > 0), "
                         f"within {MAX_COORD_M:g} m, got {b.tolist()}")
    return b


def check_init_box(box, size: tuple[int, int]) -> np.ndarray:
    """Return an initial 2D box [x, y, w, h] as (4,) float64, or raise ValueError: not 4 finite
    numbers, a non-positive size, no overlap with the (width, height) image, or a side above
    MAX_BOX_SCALE times the image's larger side (a tracker would then follow nothing)."""
    try:
        b = np.asarray(box, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"a 2D box is 4 numbers [x, y, w, h], got {box!r}") from None
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
        raise ValueError(f"init needs a finite [x, y, w, h] box with positive size, got {box}")
    w, h = float(size[0]), float(size[1])
    if not (b[0] < w and b[1] < h and b[0] + b[2] > 0 and b[1] + b[3] > 0):
        raise ValueError(f"init box {b.tolist()} does not overlap the {int(w)}x{int(h)} image")
    if max(b[2], b[3]) > MAX_BOX_SCALE * max(w, h):
        raise ValueError(f"init box {b.tolist()} is more than {MAX_BOX_SCALE:g}x the {int(w)}x{int(h)} image")
    return b
