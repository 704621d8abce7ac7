"""SiamFC's crop (runtime, no torch): padding, alignment, and the fast downscaling path against
the plain reference (pad the full-resolution patch, then area-resize)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from track3d.siamfc import crop_square


def _reference(image, center, size, out_size, border):
    h, w = image.shape[:2]
    x0, y0 = int(round(center[0] - size / 2.0)), int(round(center[1] - size / 2.0))
    n = max(int(round(size)), 1)
    big = cv2.copyMakeBorder(image, n, n, n, n, cv2.BORDER_CONSTANT, value=border)
    patch = big[y0 + n:y0 + 2 * n, x0 + n:x0 + 2 * n]
    return cv2.resize(patch, (out_size, out_size), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("size", [100.0, 600.0])            # the warpAffine and the downscaling paths
def test_wholly_outside_is_the_border_colour(size):
    img = np.full((120, 160, 3), 200, np.uint8)
    out = crop_square(img, np.array([-2000.0, 50.0]), size, 64, (10.0, 20.0, 30.0))
    assert out.shape == (64, 64, 3) and out.dtype == np.uint8
    assert np.all(out == [10, 20, 30])


@pytest.mark.parametrize("size", [60.0, 500.0])
def test_a_bright_square_lands_at_the_centre(size):
    img = np.zeros((480, 640, 3), np.uint8)
    img[200:240, 300:340] = 255                           # centre (320, 220) in continuous pixels
    out = crop_square(img, np.array([320.0, 220.0]), size, 127, (0.0, 0.0, 0.0)).astype(float)[..., 0]
    ys, xs = np.nonzero(out > 0)
    cy, cx = np.average(ys, weights=out[ys, xs]), np.average(xs, weights=out[ys, xs])
    assert abs(cx - 63.0) < 1.0 and abs(cy - 63.0) < 1.0


def test_downscaling_path_matches_the_reference():
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur((rng.random((480, 640, 3)) * 255).astype(np.uint8), (9, 9), 3)
    img[100:300, 200:400] += 60                            # an edge, so misalignment would show
    diffs = []
    for _ in range(60):
        c = rng.uniform([-100, -100], [740, 580])
        size = rng.uniform(400, 1200)                      # out/size < 0.5: the fast path
        a = crop_square(img, c, size, 191, (10.0, 20.0, 30.0)).astype(int)
        b = _reference(img, c, size, 191, (10.0, 20.0, 30.0)).astype(int)
        diffs.append(np.abs(a - b).mean())
    assert np.mean(diffs) < 2.0 and np.max(diffs) < 5.0, (np.mean(diffs), np.max(diffs))


def test_part_outside_the_image_is_exactly_the_rounded_border_colour():
    # the downscaling path frames the resized image part with OpenCV (copyMakeBorder) instead of
    # filling a numpy canvas: the frame must stay the border colour, rounded, to the pixel
    img = np.full((480, 640, 3), 200, np.uint8)
    out = crop_square(img, np.array([0.0, 240.0]), 800.0, 128, (10.4, 20.6, 30.5))
    assert out.shape == (128, 128, 3) and out.dtype == np.uint8
    assert np.all(out[:, :60] == [10, 21, 30]) and np.all(out[30:100, 70:] == 200)
