"""A tiny dependency-free progress bar on stderr (disabled when stderr is no TTY or quiet).

    for item in progress(items, desc="seq 0001", total=len(items)):
        ...
"""
from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator, TextIO, TypeVar

__all__ = ["progress", "Progress"]

T = TypeVar("T")


class Progress:
    """Counts steps and redraws one stderr line at most ~10 times a second."""

    def __init__(self, total: int | None = None, desc: str = "", enabled: bool | None = None,
                 stream: TextIO | None = None, width: int = 28):
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = enabled
        self.total = total
        self.desc = desc
        self.width = width
        self.n = 0
        self._t0 = time.perf_counter()
        self._last = 0.0

    def update(self, k: int = 1, note: str = "") -> None:
        self.n += k
        now = time.perf_counter()
        if self.enabled and (now - self._last > 0.1 or (self.total is not None and self.n >= self.total)):
            self._last = now
            self._draw(now, note)

    def _draw(self, now: float, note: str) -> None:
        rate = self.n / max(now - self._t0, 1e-9)
        if self.total:
            frac = min(self.n / self.total, 1.0)
            filled = int(round(frac * self.width))
            bar = "#" * filled + "-" * (self.width - filled)
            text = f"\r{self.desc} [{bar}] {self.n}/{self.total} {rate:.1f}/s {note}"
        else:
            text = f"\r{self.desc} {self.n} {rate:.1f}/s {note}"
        self.stream.write(text[:200].ljust(60))
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self._draw(time.perf_counter(), "")
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress(items: Iterable[T], desc: str = "", total: int | None = None, enabled: bool | None = None,
             stream: TextIO | None = None) -> Iterator[T]:
    """Iterate `items`, drawing a bar; `enabled=False` (e.g. --quiet) draws nothing."""
    if total is None:
        try:
            total = len(items)  # type: ignore[arg-type]
        except TypeError:
            total = None
    with Progress(total, desc, enabled, stream) as bar:
        for item in items:
            yield item
            bar.update()
