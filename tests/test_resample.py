"""The trackers' bilinear crop (track3d.resample): OpenCV 5.0.0.93's bytes whatever OpenCV is
installed, the compiled kernel equal to its numpy reference, hand cases of the arithmetic."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from track3d import resample as R
from track3d.siamfc import crop_square

FIXTURE = Path(__file__).parent / "data" / "warp_opencv500.npz"


def _fixture_cases():
    d = np.load(FIXTURE)
    for i, (sx, sy, tx, ty, ow, oh, b0, b1, b2, rep) in enumerate(d["cases"]):
        yield (d[f"image{i}"], (sx, sy), (tx, ty), (int(ow), int(oh)), (b0, b1, b2),
               "replicate" if rep else "constant", d[f"out{i}"])


@pytest.mark.parametrize("warp", [R.warp_axis_aligned_numpy, R.warp_axis_aligned], ids=["numpy", "compiled"])
def test_both_give_opencv_500_bytes(warp):
    n = 0
    for img, scale, offset, size, border_value, border, want in _fixture_cases():
        got = warp(img, scale, offset, size, border_value, border)
        assert got.dtype == np.uint8 and got.shape == want.shape
        assert np.array_equal(got, want), (scale, offset, size, border, int((got != want).sum()))
        n += 1
    assert n == 48


def test_the_compiled_kernel_is_the_reference_bit_for_bit():
    rng = np.random.default_rng(7)
    assert R.HAVE_EXTENSION
    for i in range(150):
        h, w = int(rng.integers(1, 70)), int(rng.integers(1, 90))
        img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        sx = float(np.exp(rng.uniform(-0.7, 2.5)))
        sy = sx if i % 2 else float(np.exp(rng.uniform(-0.7, 2.5)))
        size = (int(rng.integers(1, 100)), int(rng.integers(1, 60)))
        offset = (float(rng.uniform(-3 * sx * w, 2 * size[0])), float(rng.uniform(-3 * sy * h, 2 * size[1])))
        if i % 10 == 0:
            offset = (1e7, -1e7)                           # far outside: all border, no overflow
        border_value = tuple(rng.uniform(-30, 290, 3))
        for border in ("constant", "replicate"):
            a = R.warp_axis_aligned_numpy(img, (sx, sy), offset, size, border_value, border)
            b = R.warp_axis_aligned(img, (sx, sy), offset, size, border_value, border)
            assert np.array_equal(a, b), (i, border, int((a != b).sum()))


def test_fma32_rounds_once_where_float64_would_round_twice():
    # a * b + c = 1 + 2^-23 + 2^-24 - 2^-70: just below the float32 midpoint between 1 + 2^-23
    # and 1 + 2^-22, so the fma is 1 + 2^-23; float64 first rounds it onto the midpoint, and the
    # tie then goes to the even 1 + 2^-22
    a = np.float32(1 + 2.0 ** -23)
    b = np.float32((1 - 2.0 ** -23) * 2.0 ** -24)
    c = np.float32(1 + 2.0 ** -23)
    naive = np.float32(np.float64(a) * np.float64(b) + np.float64(c))
    assert naive == np.float32(1 + 2.0 ** -22)
    assert R.fma32(a, b, c) == np.float32(1 + 2.0 ** -23)
    assert R.fma32(np.float32(3.0), np.float32(0.5), np.float32(-1.0)) == np.float32(0.5)   # exact cases stay


def test_hand_cases_of_the_arithmetic():
    img = np.zeros((1, 3, 3), np.uint8)
    img[0, :, 0] = [0, 101, 200]
    # identity: the image itself
    assert np.array_equal(R.warp_axis_aligned(img, (1.0, 1.0), (0.0, 0.0), (3, 1)), img)
    # half a pixel right: output x samples source x - 0.5; (0 + 101) / 2 = 50.5 rounds to the even 50,
    # (101 + 200) / 2 = 150.5 to 150; column 0 mixes the border colour 7 with 0: 3.5 -> 4
    for warp in (R.warp_axis_aligned, R.warp_axis_aligned_numpy):
        out = warp(img, (1.0, 1.0), (0.5, 0.0), (3, 1), (7.0, 7.0, 7.0))
        assert out[0, :, 0].tolist() == [4, 50, 150]
        # the row under the image (border colour) has weight 0: channel 1 stays 0 inside
        assert out[0, 1:, 1].tolist() == [0, 0]
        rep = warp(img, (1.0, 1.0), (0.5, 0.0), (3, 1), border="replicate")
        assert rep[0, :, 0].tolist() == [0, 50, 150]
    # the border colour is rounded half to even and clamped, as OpenCV's saturate_cast
    out = R.warp_axis_aligned(img, (1.0, 1.0), (100.0, 0.0), (2, 1), (2.5, 300.0, -4.0))
    assert out.reshape(-1, 3).tolist() == [[2, 255, 0], [2, 255, 0]]


def test_crop_square_is_the_warp():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    center, size, out_size = np.array([70.3, 40.8]), 90.0, 127    # out / size >= 0.5: the warp path
    s = out_size / size
    offset = (out_size / 2.0 - 0.5 - s * (center[0] - 0.5), out_size / 2.0 - 0.5 - s * (center[1] - 0.5))
    want = R.warp_axis_aligned_numpy(img, (s, s), offset, (out_size, out_size), (9.0, 8.0, 7.0))
    assert np.array_equal(crop_square(img, center, size, out_size, (9.0, 8.0, 7.0)), want)


@pytest.mark.parametrize("kwargs, match", [
    (dict(image=np.zeros((4, 4), np.uint8)), "uint8 image"),
    (dict(image=np.zeros((4, 4, 3), np.float32)), "uint8 image"),
    (dict(scale=(0.0, 1.0)), "positive finite scales"),
    (dict(offset=(np.nan, 0.0)), "finite offsets"),
    (dict(size=(0, 5)), "at least 1 x 1"),
    (dict(border="reflect"), "border must be"),
    (dict(border_value=(1.0, np.inf, 0.0)), "three finite numbers"),
    (dict(scale=(1e-45, 1.0)), "degenerate in float32"),          # the inverse overflows float32
    (dict(offset=(1e39, 0.0)), "degenerate in float32"),
])
def test_bad_input_is_one_clear_error(kwargs, match):
    args = dict(image=np.zeros((4, 4, 3), np.uint8), scale=(1.0, 1.0), offset=(0.0, 0.0), size=(4, 4),
                border_value=(0.0, 0.0, 0.0), border="constant")
    args.update(kwargs)
    for warp in (R.warp_axis_aligned, R.warp_axis_aligned_numpy):
        with pytest.raises(ValueError, match=match):
            warp(args["image"], args["scale"], args["offset"], args["size"], args["border_value"], args["border"])


def test_the_crops_never_call_opencvs_warp(monkeypatch):
    # the bytes of a crop must not depend on the installed OpenCV's warpAffine
    import cv2

    def refuse(*a, **k):
        raise AssertionError("cv2.warpAffine called")

    monkeypatch.setattr(cv2, "warpAffine", refuse)
    img = np.random.default_rng(1).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    for size in (40.0, 120.0, 400.0):          # upscaling, mild downscaling, the halving path
        assert crop_square(img, np.array([80.0, 60.0]), size, 127, (1.0, 2.0, 3.0)).shape == (127, 127, 3)


def test_source_coordinates_past_float32_stay_border():
    # a scale of 1e-30 leaves a finite inverse (1e30): from the second column and row on the
    # source coordinates lie far past 2^30; clipped there, they stay outside the image (border)
    img = np.full((5, 5, 3), 200, np.uint8)
    for warp in (R.warp_axis_aligned, R.warp_axis_aligned_numpy):
        out = warp(img, (1e-30, 1e-30), (0.0, 0.0), (20, 3), (1.0, 2.0, 3.0))
        assert np.all(out[:, 1:] == [1, 2, 3]) and np.all(out[1:] == [1, 2, 3])
        assert out[0, 0].tolist() == [200, 200, 200]          # output (0, 0) still samples source (0, 0)


def test_the_gray_warp_is_opencv_500_on_rotations():
    # the training's motion-blur kernel: a line rotated about its centre; OpenCV 5.0.0.93's own
    # warps of it (all scalar-tail columns) and of a 20 x 18 image (SIMD body and tail columns),
    # committed in the fixture
    d = np.load(FIXTURE)
    for i, (m, size) in enumerate(zip(d["gray_maps"], d["gray_sizes"])):
        got = R.warp_affine_gray_numpy(d[f"gray_image{i}"], m.reshape(2, 3), tuple(int(v) for v in size))
        assert got.dtype == np.float32 and np.array_equal(got, d[f"gray_out{i}"]), i
    one = np.ones((3, 3), np.float32)
    with pytest.raises(ValueError, match="finite and invertible"):          # its determinant underflows to 0
        R.warp_affine_gray_numpy(one, np.array([[1e-300, 0, 0], [0, 1e-300, 0]]), (3, 3))
    with pytest.raises(ValueError, match="no finite float32 inverse"):      # its inverse 1e39 is past float32
        R.warp_affine_gray_numpy(one, np.array([[1e-39, 0, 0], [0, 1e-39, 0]]), (3, 3))


def test_the_training_never_calls_opencvs_warp(monkeypatch):
    # the training pairs' crops and the motion-blur kernel: the same bytes whatever OpenCV is installed
    import cv2
    data = pytest.importorskip("track3d_train.edgetrack.data")

    def refuse(*a, **k):
        raise AssertionError("cv2.warpAffine called")

    monkeypatch.setattr(cv2, "warpAffine", refuse)
    k = data._motion_kernel(np.random.default_rng(0), 7)
    assert k.shape == (7, 7) and k.dtype == np.float32 and abs(float(k.sum()) - 1.0) < 1e-5
