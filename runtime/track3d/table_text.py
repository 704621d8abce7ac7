"""Numbers as table cells, and markdown tables: the one spelling of a missing value.

Used by the evaluation's summary table, `track3d bench` and the benchmarks' markdown, so that
a value that was not measured (None, nan) reads "-" everywhere.
"""
from __future__ import annotations

import math

__all__ = ["MISSING", "cell", "markdown_table"]

MISSING = "-"


def cell(value, fmt: str = "{:.3f}") -> str:
    """`fmt.format(value)`, or MISSING for None and non-finite floats."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return MISSING
    return fmt.format(value)


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A markdown table of already formatted cells (no trailing newline)."""
    def line(cells) -> str:   # an empty cell is "| |", as people write it
        return "|" + "|".join(f" {c} " if c else " " for c in cells) + "|"

    return "\n".join([line(header), "|" + "---|" * len(header)] + [line(r) for r in rows])
