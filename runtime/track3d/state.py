"""Plain-data checkpoints: numpy arrays <-> JSON-able builtins, bit-exact.

A tracker state (``Track3D.get_state()``) is made of dicts, lists, str, int, float, bool, None
and numpy arrays. :func:`to_plain` turns it into builtins only (an array becomes
``{"__ndarray__": base64 bytes, "dtype": ..., "shape": [...]}``), so it pickles and
``json.dumps`` without loss; :func:`from_plain` undoes it. Floats survive JSON exactly
(Python writes the shortest repr that reads back to the same double).
"""
from __future__ import annotations

import base64

import numpy as np

__all__ = ["to_plain", "from_plain"]

_ARRAY = "__ndarray__"


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
            raw = base64.b64decode(x[_ARRAY])
            return np.frombuffer(raw, dtype=np.dtype(x["dtype"])).reshape(x["shape"]).copy()
        return {k: from_plain(v) for k, v in x.items()}
    if isinstance(x, list):
        return [from_plain(v) for v in x]
    return x
