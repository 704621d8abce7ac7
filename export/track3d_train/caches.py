"""Reading the training caches (`prepare`'s output) with one kind of error for a path that is not one.

A cache given on the command line may be missing, a folder where a file is expected (or the
reverse), an empty or truncated file, or another file altogether. Each reader turns that into a
`CacheError` naming the path and the command that makes the right cache; it is a ValueError, so
`track3d-train` prints it as one line (never numpy's or zipfile's traceback, nor numpy's hint to
load a file "unsafely" with allow_pickle).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["CacheError", "not_a_cache", "load_npy", "load_npz", "read_json"]


class CacheError(ValueError):
    """A path given as a training cache is not one; the message says why and what makes one."""


def not_a_cache(path: str | Path, kind: str, maker: str, why: str) -> CacheError:
    return CacheError(f"{path} is not {kind} made by `{maker}` ({why})")


def _file(path: Path, kind: str, maker: str) -> Path:
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist: give {kind} made by `{maker}`")
    if path.is_dir():
        raise not_a_cache(path, kind, maker, "a folder")
    if path.stat().st_size == 0:
        raise not_a_cache(path, kind, maker, "an empty file")
    return path


def load_npy(path: str | Path, kind: str, maker: str, mmap_mode: str | None = None) -> np.ndarray:
    """np.load of one array file (.npy, no pickles) of a cache; CacheError if it is none."""
    p = _file(Path(path), kind, maker)
    try:
        arr = np.load(p, mmap_mode=mmap_mode, allow_pickle=False)
    except PermissionError:
        raise
    except Exception:   # EOFError, ValueError (pickles, a bad header), OSError: not a whole .npy file
        raise not_a_cache(p, kind, maker, "not a complete .npy array file") from None
    if not isinstance(arr, np.ndarray):   # an .npz archive
        raise not_a_cache(p, kind, maker, "an .npz archive, not an .npy array file")
    return arr


def load_npz(path: str | Path, kind: str, maker: str, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The arrays `keys` of an .npz archive (read whole, file closed); CacheError if it is not an
    archive holding them."""
    p = _file(Path(path), kind, maker)
    try:
        z = np.load(p, allow_pickle=False)
    except PermissionError:
        raise
    except Exception:   # EOFError, BadZipFile, ValueError (pickles): not an .npz archive
        raise not_a_cache(p, kind, maker, "not a complete .npz archive") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise not_a_cache(p, kind, maker, "an .npy array file, not an .npz archive")
    with z:
        missing = [k for k in keys if k not in z.files]
        if missing:
            names = ", ".join(missing[:3]) + (", ..." if len(missing) > 3 else "")
            raise not_a_cache(p, kind, maker, f"an .npz archive without {names}")
        try:
            return {k: z[k] for k in keys}
        except Exception:   # a damaged member (BadZipFile, zlib.error, ValueError, EOFError)
            raise not_a_cache(p, kind, maker, "a damaged .npz archive") from None


def read_json(path: str | Path, kind: str, maker: str, keys: tuple[str, ...] = ()) -> dict:
    """A cache's JSON index (an object with `keys`); CacheError if it is not one."""
    p = _file(Path(path), kind, maker)
    try:
        d = json.loads(p.read_bytes())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise not_a_cache(p, kind, maker, "not a JSON file") from None
    if not isinstance(d, dict):
        raise not_a_cache(p, kind, maker, "JSON, but not an object")
    missing = [k for k in keys if k not in d]
    if missing:
        raise not_a_cache(p, kind, maker, f"no {', '.join(missing)} in it")
    return d
