"""Where benchmark results go: ./bench-results/<name> under the current folder by default,
never into the repository unless asked (pass --out benchmarks/results/... to update the
committed files)."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["DEFAULT_OUT", "add_out_argument", "out_dir_problem", "relative_to"]

DEFAULT_OUT = Path("bench-results")


def add_out_argument(ap: argparse.ArgumentParser, name: str = "", flag: str = "--out",
                     committed: str = "benchmarks/results") -> None:
    """The output folder option, default DEFAULT_OUT / name; the help says where the committed
    results are."""
    default = DEFAULT_OUT / name if name else DEFAULT_OUT
    ap.add_argument(flag, type=Path, default=default,
                    help=f"output folder (default: ./{default}; the committed results: {committed})")


def out_dir_problem(path: str | Path) -> str | None:
    """Why results could not be written into the folder `path` (a file there or in its way, no
    permission to create it), else None; checked before a run, without creating anything (a file
    given as the folder ended in FileExistsError after all the timing)."""
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            return f"{p} is a file, not a folder"
        return None if os.access(p, os.W_OK | os.X_OK) else f"{p}: no permission to write into it"
    parent = p.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"cannot create {p}: {parent} is a file, not a folder"
    return None if os.access(parent, os.W_OK | os.X_OK) else f"cannot create {p}: no permission to write into {parent}"


def relative_to(path: str | Path, base: str | Path) -> str:
    """`path` as recorded in a result file: relative to `base` (the output folder the record
    lives in), POSIX separators, so a record never carries the machine's folders whatever
    --out was given."""
    return Path(os.path.relpath(Path(path).resolve(), Path(base).resolve())).as_posix()
