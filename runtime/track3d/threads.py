"""Thread counts: the one check of a count asked for, and the process-wide settings (OpenCV's
pool) that follow it."""
from __future__ import annotations

import os

__all__ = ["THREADS_PER_CPU", "max_threads", "threads_rule", "check_threads", "set_threads"]

# More threads than CPUs only queue for them; a few per CPU is an experiment (oversubscription),
# thousands are a typo: `--threads 99999` had onnxruntime start 99,999 threads a session, which
# took every process slot of the machine (nothing else could fork) before it failed.
THREADS_PER_CPU = 4


def max_threads() -> int:
    """The most threads a model may be given: THREADS_PER_CPU per CPU of this machine."""
    return THREADS_PER_CPU * max(os.cpu_count() or 1, 1)


def threads_rule() -> str:
    """What a thread count must be, in words (the one wording of every message about it)."""
    return f"an integer from 1 to {max_threads()} ({THREADS_PER_CPU} per CPU of this machine's {os.cpu_count() or 1})"


def check_threads(threads) -> int:
    """`threads` as an int in 1 .. max_threads(); ValueError (one line) otherwise."""
    try:
        n = int(threads)
    except (TypeError, ValueError, OverflowError):   # inf: OverflowError
        n = None
    if n is None or n != threads or not 1 <= n <= max_threads():
        raise ValueError(f"threads must be {threads_rule()}, got {threads!r}")
    return n


def set_threads(threads: int) -> None:
    """OpenCV's own thread pool follows --threads too, so that FPS at 1 thread means one thread."""
    import cv2

    cv2.setNumThreads(check_threads(threads))
