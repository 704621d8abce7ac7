"""Plain-data checkpoints: numpy arrays <-> JSON-able builtins, bit-exact.

A tracker state (``Track3D.get_state()``) is made of dicts, lists, str, int, float, bool, None
and numpy arrays. :func:`to_plain` turns it into builtins only (an array becomes
``{"__ndarray__": base64 bytes, "dtype": ..., "shape": [...]}``), so it pickles and
``json.dumps`` without loss; :func:`from_plain` undoes it. Floats survive JSON exactly
(Python writes the shortest repr that reads back to the same double).

A state read back may be damaged (a flipped bit in a file, a hand edit, another program's
JSON): :func:`from_plain` and the ``read_*`` helpers below raise ValueError with one line on
anything that is not what the writer wrote, so that each ``set_state`` can check every field
before it changes anything (:func:`damaged` turns any other slip of a reader into that one line).
"""
from __future__ import annotations

import base64
import binascii
import contextlib
import math
import re

import numpy as np

__all__ = ["to_plain", "from_plain", "damaged", "read_flag", "read_int", "read_float", "read_array", "read_box",
           "read_kernel"]

_ARRAY = "__ndarray__"
_DTYPE = re.compile(r"[<>|=][biuf][1248]")


def to_plain(x):
    """Arrays and numpy scalars -> builtins, recursively (tuples become lists)."""
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        if a.dtype == object:
            raise ValueError("object arrays cannot be stored in a tracker state")
        return {_ARRAY: base64.b64encode(a.tobytes()).decode("ascii"), "dtype": a.dtype.str,
                "shape": list(a.shape)}
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, dict):
        return {str(k): to_plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [to_plain(v) for v in x]
    if x is None or isinstance(x, (str, int, float, bool)):
        return x
    raise ValueError(f"a tracker state holds only arrays and builtins, got {type(x).__name__}")


def from_plain(x):
    """Inverse of :func:`to_plain` (arrays come back writable, with their dtype and shape)."""
    if isinstance(x, dict):
        if _ARRAY in x:
            return _array_of(x)
        return {k: from_plain(v) for k, v in x.items()}
    if isinstance(x, list):
        return [from_plain(v) for v in x]
    return x


def _array_of(x: dict) -> np.ndarray:
    """One array record back; ValueError if it is not one `to_plain` wrote."""
    try:
        # the form to_plain writes (a.dtype.str: '<f8', '|b1', ...), checked before numpy parses
        # it: a damaged one such as ',' or 'i4,(' made np.dtype raise SyntaxError
        if not (isinstance(x["dtype"], str) and _DTYPE.fullmatch(x["dtype"])):
            raise ValueError(f"dtype {x['dtype']!r:.40} is not a number type")
        dtype = np.dtype(x["dtype"])
        shape = x["shape"]
        if not isinstance(shape, list) or any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in shape):
            raise ValueError(f"shape {shape!r:.40}")
        raw = base64.b64decode(x[_ARRAY], validate=True)
        return np.frombuffer(raw, dtype=dtype).reshape(shape).copy()
    except (KeyError, TypeError, ValueError, binascii.Error, OverflowError) as e:
        raise ValueError(f"damaged array in a tracker state: {_line(e)}") from None


def _line(e: BaseException) -> str:
    """An exception as one short line (numpy's messages may quote whole arrays over lines)."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text[:160]}"


@contextlib.contextmanager
def damaged(what: str):
    """Turn any slip of a state reader (a missing key, a wrong type, a bad number) into
    ``ValueError("damaged <what> state: ...")`` on one line."""
    try:
        yield
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as e:
        if isinstance(e, ValueError) and str(e).startswith("damaged ") and "\n" not in str(e):
            raise
        raise ValueError(f"damaged {what} state: {_line(e)}") from None


def read_flag(x, what: str) -> bool:
    """A true / false field (not 0 / 1, not a string)."""
    if not isinstance(x, bool):
        raise ValueError(f"{what} must be true or false, got {x!r:.40}")
    return x


def read_int(x, what: str, lo: int = 0) -> int:
    """An integer field (not a bool, not a float) of at least `lo`."""
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or int(x) < lo:
        raise ValueError(f"{what} must be an integer >= {lo}, got {x!r:.40}")
    return int(x)


def read_float(x, what: str, lo: float = -math.inf, hi: float = math.inf, nan_ok: bool = False,
               inf_ok: bool = False) -> float:
    """A real number in [lo, hi]; nan only when `nan_ok`, +-inf only when `inf_ok`."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number, got {x!r:.40}")
    v = float(x)
    if math.isnan(v):
        if nan_ok:
            return v
        raise ValueError(f"{what} is nan")
    if math.isinf(v) and not inf_ok:
        raise ValueError(f"{what} is {v}")
    if not lo <= v <= hi:
        raise ValueError(f"{what} = {v} is outside [{lo}, {hi}]")
    return v


def read_array(x, what: str, shape: tuple, dtype=np.float64, finite: bool = True,
               positive: bool = False) -> np.ndarray:
    """A numeric array of `shape` (-1: any length on that axis), a fresh copy; finite unless told,
    every value above 0 when `positive`."""
    if isinstance(x, (str, bytes, dict)) or x is None:
        raise ValueError(f"{what} must be an array of numbers, got {type(x).__name__}")
    try:
        a = np.array(x, dtype=dtype)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{what} must be an array of numbers") from None
    if a.ndim != len(shape) or any(w >= 0 and w != n for w, n in zip(shape, a.shape)):
        raise ValueError(f"{what} has shape {a.shape}, not {tuple(shape)}")
    if finite and a.dtype.kind == "f" and not np.isfinite(a).all():
        raise ValueError(f"{what} is not finite")
    if positive and not (a > 0).all():
        raise ValueError(f"{what} has a value <= 0")
    return a


def read_box(x, what: str, n: int, unset_ok: bool = False, empty_ok: bool = False) -> np.ndarray:
    """A box of `n` = 4 (x, y, w, h: pixels) or 6 (cx, cy, cz, sx, sy, sz: metres) float64
    values, finite, its sizes (the last half: w, h or sx, sy, sz) positive (or zero when
    `empty_ok`); all nan when `unset_ok`."""
    a = read_array(x, what, (n,), finite=False)
    if unset_ok and np.isnan(a).all():
        return a
    if not np.isfinite(a).all():
        raise ValueError(f"{what} is not finite")
    sizes = a[n // 2:]
    if not ((sizes >= 0.0) if empty_ok else (sizes > 0.0)).all():
        raise ValueError(f"{what} has a size {'< 0' if empty_ok else '<= 0'}")
    return a


def read_kernel(x, what: str, model_shape) -> np.ndarray:
    """A network's cached feature (float32) whose shape fits the model input's `model_shape`
    (each dim an int, or None / a name where the model leaves it free)."""
    a = read_array(x, what, (-1,) * len(model_shape), np.float32)
    if any(isinstance(w, int) and w > 0 and w != n for w, n in zip(model_shape, a.shape)):
        raise ValueError(f"{what} of shape {a.shape} does not fit this model")
    return a
