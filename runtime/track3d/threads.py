"""Thread counts that are process-wide settings (OpenCV's pool), one place for them."""
from __future__ import annotations

__all__ = ["set_threads"]


def set_threads(threads: int) -> None:
    """OpenCV's own thread pool follows --threads too, so that FPS at 1 thread means one thread."""
    import cv2

    cv2.setNumThreads(int(threads))
