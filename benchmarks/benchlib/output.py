"""Where benchmark results go: ./bench-results/<name> under the current folder by default,
never into the repository unless asked (pass --out benchmarks/results/... to update the
committed files)."""
from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["DEFAULT_OUT", "add_out_argument", "relative_to"]

DEFAULT_OUT = Path("bench-results")


def add_out_argument(ap: argparse.ArgumentParser, name: str = "", flag: str = "--out",
                     committed: str = "benchmarks/results") -> None:
    """The output folder option, default DEFAULT_OUT / name; the help says where the committed
    results are."""
    default = DEFAULT_OUT / name if name else DEFAULT_OUT
    ap.add_argument(flag, type=Path, default=default,
                    help=f"output folder (default: ./{default}; the committed results: {committed})")


def relative_to(path: str | Path, base: str | Path) -> str:
    """`path` as recorded in a result file: relative to `base` (the output folder the record
    lives in), POSIX separators, so a record never carries the machine's folders whatever
    --out was given."""
    return Path(os.path.relpath(Path(path).resolve(), Path(base).resolve())).as_posix()
