"""The output file of a `track3d-sim` command (--out): checked before any work, its folder made
at write time (as `track3d eval --out` and the runtime's writers make theirs)."""
from __future__ import annotations

from pathlib import Path

from .errors import SimError


def check_out(out: str | Path, what: str, suffixes: tuple[str, ...] | None = None) -> Path:
    """`out` as a Path; a folder, or (with `suffixes`) another extension, is a one-line SimError."""
    out = Path(out)
    if out.is_dir():
        raise SimError(f"--out {out} is a folder: give the {what} file to write")
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise SimError(f"--out {out.name}: the {what} must end in {', '.join(suffixes)}")
    return out


def make_parent(out: Path) -> Path:
    """Create the folders above `out` (a file standing in their way is a one-line SimError)."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        block = next((p for p in reversed(out.parents) if p.exists() and not p.is_dir()), None)
        why = f"{block} is a file, not a folder" if block is not None else (e.strerror or str(e))
        raise SimError(f"cannot create the folder of --out {out}: {why}") from None
    return out
