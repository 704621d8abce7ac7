"""A3BoxNet's box codings (track3d.size_coding): hand cases of normalise, labels and decode."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxes import SIZE_TEMPLATES, size_class_of
from track3d.size_coding import SIZE_CODINGS, remap_extent, remap_length, size_coding


def _outputs(cls: int, r, other: float = 9.0):
    scores = np.zeros((1, 14))
    scores[0, cls] = 3.0
    res = np.full((1, 14, 3), other)                  # other classes' residuals must be ignored
    res[0, cls] = r
    return scores, res


def test_points_coding_decode_hand_case():
    scores, res = _outputs(1, [0.1, -0.1, 0.0])       # class 1: template [1/2, 1, 1]
    box = size_coding("points").decode([[1.0, 2.0, 3.0]], [4.0], [[0.5, 0, 0]], [[0, 0.25, 0]], scores, res)
    np.testing.assert_allclose(box, [[1.5, 2.25, 3.0, 2.4, 3.6, 4.0]], atol=1e-12)


def test_decode_batch_and_clamp():
    scores = np.zeros((2, 14))
    scores[0, 0] = scores[1, 2] = 1.0
    res = np.zeros((2, 14, 3))
    res[1, 2] = [-0.5, 0, 0]                          # 1/3 - 0.5 < 0: clamped to 1 mm, never negative
    boxes = size_coding("points").decode(np.zeros((2, 3)), np.array([2.0, 3.0]), np.zeros((2, 3)),
                                         np.ones((2, 3)), scores, res)
    np.testing.assert_allclose(boxes[0], [1, 1, 1, 2, 2, 2])
    assert boxes[1, 3] == pytest.approx(1e-3) and boxes[1, 4] == pytest.approx(3.0)


def test_extent_coding_hand_case():
    p = np.array([[0, 0, 10], [2, 0, 10], [0, 1, 10.5], [2, 1, 10]], np.float64)
    e = remap_extent(p)
    np.testing.assert_allclose(e, [2.0, 1.0, 0.5])
    np.testing.assert_allclose(remap_extent(p * [1, 1, 0] + [0, 0, 10]), [2.0, 1.0, 0.2])  # flat: 10% of 2 m
    coding = size_coding("extent")
    centred, ref, scale = coding.normalise(p)
    np.testing.assert_allclose(scale, e)
    np.testing.assert_allclose(ref, [1.0, 0.5, 10.125])
    # labels: size / E - 1 per axis; decoding E * (1 + r) of the predicted class gives the size back
    cls, res, sc = coding.labels(np.array([2.2, 1.0, 1.5]), e)
    np.testing.assert_allclose(res, [0.1, 0.0, 2.0])
    np.testing.assert_allclose(sc, e)
    box = coding.decode(ref, scale, np.zeros(3), np.array([0.0, 0.0, 0.5]), *_outputs(int(cls), res))
    np.testing.assert_allclose(box, [[1.0, 0.5, 10.625, 2.2, 1.0, 1.5]], atol=1e-12)


def test_frustum_coding_hand_case():
    """x / y reference and extents from the whole frustum's bounds, z from the sample."""
    sample = np.array([[0, 0, 10], [2, 0, 10], [0, 1, 10.5], [2, 1, 10]], np.float64)
    bounds = np.array([[-1.0, -0.5, 9.0], [3.0, 1.5, 30.0]])   # wider: points the sample missed
    coding = size_coding("frustum")
    assert coding.needs_bounds and coding.per_axis
    centred, ref, scale = coding.normalise(sample, bounds)
    np.testing.assert_allclose(ref, [1.0, 0.5, 10.125])         # x, y: bounds' middle; z: centroid
    np.testing.assert_allclose(scale, [4.0, 2.0, 0.5])          # x, y: bounds; z: sample (not 21 m)
    np.testing.assert_allclose(centred, sample - ref, atol=1e-6)
    assert centred.dtype == np.float32
    cls, res, sc = coding.labels(np.array([4.4, 2.0, 1.5]), scale)
    np.testing.assert_allclose(res, [0.1, 0.0, 2.0])
    box = coding.decode(ref, scale, [[0.5, 0, 0]], [[0, 0, 0.5]], *_outputs(int(cls), res))
    np.testing.assert_allclose(box, [[1.5, 0.5, 10.625, 4.4, 2.0, 1.5]], atol=1e-12)
    # the 10% floor applies to the bounds' extents too
    flat = coding.normalise(sample * [1, 0, 1], np.array([[-1.0, 0.0, 9.0], [3.0, 0.0, 9.0]]))[2]
    np.testing.assert_allclose(flat, [4.0, 0.4, 0.5])
    # batches: bounds (B, 2, 3) beside points (B, N, 3)
    _, refs, scales = coding.normalise(np.stack([sample, sample + 1]), np.stack([bounds, bounds + 1]))
    np.testing.assert_allclose(refs[1], ref + 1)
    np.testing.assert_allclose(scales[1], scale)


def test_frustum_coding_refuses_missing_or_misshapen_bounds():
    coding = size_coding("frustum")
    with pytest.raises(ValueError, match="needs the frustum's bounds"):
        coding.normalise(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="bounds must have shape"):
        coding.normalise(np.zeros((4, 3)), np.zeros((3, 2)))


@pytest.mark.parametrize("name", ["points", "paper"])
def test_length_labels_round_trip(name):
    rng = np.random.default_rng(0)
    sizes = rng.uniform(1, 20, size=(50, 3))
    length = sizes.max(axis=1) * rng.uniform(0.5, 1.0, size=50)   # points see part of the object
    cls, res, scale = size_coding(name).labels(sizes, length)
    np.testing.assert_array_equal(cls, size_class_of(sizes)[0])
    # decoding multiplies by L of the points; the "points" label makes that exact
    decoded = (SIZE_TEMPLATES[cls] + res) * length[:, None]
    if name == "points":
        np.testing.assert_allclose(decoded, sizes, rtol=1e-12)
        np.testing.assert_allclose(scale, length)
    else:
        np.testing.assert_allclose(decoded, sizes * (length / sizes.max(axis=1))[:, None], rtol=1e-12)
        np.testing.assert_allclose(scale, sizes.max(axis=1))


def test_points_normalise_and_remap_length():
    p = np.array([[0, 0, 10], [2, 0, 10], [0, 1, 13], [2, 1, 11]], np.float32)
    centred, centroid, L = size_coding("points").normalise(p)
    np.testing.assert_allclose(centroid, [1, 0.5, 11])
    np.testing.assert_allclose(centred.mean(axis=0), 0, atol=1e-6)
    assert centred.dtype == np.float32 and L == pytest.approx(3.0)
    assert remap_length(np.ones((1, 3))) == pytest.approx(1e-3)  # one point: floored, no divide by 0


def test_every_coding_round_trips_its_labels():
    """labels -> decode with zero centre offsets gives the size back (per-axis codings exactly;
    the paper's coding by design only up to L / max(size))."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(-1, 1, size=(5, 64, 3)) * [2, 1.5, 1] + [0, 0, 20]
    bounds = np.stack([pts.min(axis=1) - 0.1, pts.max(axis=1) + 0.1], axis=1)
    sizes = rng.uniform(1.5, 4, size=(5, 3))
    for name, coding in SIZE_CODINGS.items():
        if name == "paper":
            continue
        _, ref, scale = coding.normalise(pts, bounds)
        cls, res, _ = coding.labels(sizes, scale)
        scores = np.zeros((5, 14))
        scores[np.arange(5), cls] = 1.0
        residuals = np.zeros((5, 14, 3))
        residuals[np.arange(5), cls] = res
        boxes = coding.decode(ref, scale, np.zeros((5, 3)), np.zeros((5, 3)), scores, residuals)
        np.testing.assert_allclose(boxes[:, 3:], sizes, rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(boxes[:, :3], ref, err_msg=name)


def test_unknown_coding_is_named():
    with pytest.raises(ValueError, match="unknown size coding 'cube'.*points, paper, extent, frustum"):
        size_coding("cube")
