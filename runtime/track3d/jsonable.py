"""Measurements as JSON: the one conversion of numbers (numpy, nan) and the one writer.

Reports and benchmark records are read by people and by other programs: a non-finite float
becomes null (JSON has no NaN), numpy scalars and arrays become plain numbers and lists, and
floats keep 6 decimals (what a measurement's noise allows, and stable diffs of committed files).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["jsonable", "write_json"]

DECIMALS = 6


def jsonable(x):
    """`x` with every float rounded to DECIMALS (nan / inf -> None), numpy values made plain,
    tuples and arrays made lists; dict keys and other values as they are."""
    if isinstance(x, (float, np.floating)):
        return None if not math.isfinite(float(x)) else round(float(x), DECIMALS)
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in (x.tolist() if isinstance(x, np.ndarray) else x)]
    return x


def write_json(path: str | Path, obj, indent: int = 1) -> Path:
    """Write jsonable(obj) to `path` (parent folders made); returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(jsonable(obj), indent=indent))
    return p
