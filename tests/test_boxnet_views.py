"""Test-time views of the A3BoxNet estimator (track3d.boxnet, VIEWS): one view is the plain pass,
K views average K passes over their own samples and mirrors, computed here by hand."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxnet import MIRRORS, A3BoxNetEstimator, average_boxes, views_for
from track3d.frustum import sample_points


@pytest.fixture(scope="module")
def cloud():
    rng = np.random.default_rng(4)
    p = (rng.normal(size=(3000, 3)) * [1.2, 0.8, 0.6] + [1.5, -0.7, 14.0]).astype(np.float32)
    return p, np.stack([p.min(0), p.max(0)]).astype(np.float64)


def test_average_boxes_hand_case():
    boxes = np.array([[0.0, 1.0, 10.0, 1.0, 2.0, 3.0],
                      [2.0, 3.0, 12.0, 4.0, 8.0, 3.0]])
    np.testing.assert_allclose(average_boxes(boxes), [1.0, 2.0, 11.0, 2.0, 4.0, 3.0])


def test_one_view_is_the_plain_pass(cloud):
    pts, b = cloud
    est = A3BoxNetEstimator(views=1)
    sample = sample_points(pts, est.num_points, est.seed)
    centred, ref, scale = est.coding.normalise(sample[None], b[None])
    plain = est.coding.decode(ref, scale, *est.infer(centred, [-1]))[0]
    np.testing.assert_array_equal(est.estimate(pts, -1, b), plain)
    assert A3BoxNetEstimator().views == views_for(None) == 1


def test_views_average_mirrored_passes_computed_by_hand(cloud):
    pts, b = cloud
    est = A3BoxNetEstimator(views=4)
    boxes = []
    for k in range(4):
        axes = list(MIRRORS[k])
        s = sample_points(pts, est.num_points, est.seed + k)
        s[:, axes] *= -1
        bk = b.copy()
        bk[:, axes] = -b[::-1][:, axes]          # a mirrored axis: min = -max, max = -min
        centred, ref, scale = est.coding.normalise(s[None], bk[None])
        box = est.coding.decode(ref, scale, *est.infer(centred, [-1]))[0]
        box[axes] *= -1
        boxes.append(box)
    boxes = np.array(boxes)
    want = np.concatenate([boxes[:, :3].mean(0), np.exp(np.log(boxes[:, 3:]).mean(0))])
    got = est.estimate(pts, -1, b)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert not np.allclose(boxes[0], boxes[1])   # the views do differ
    np.testing.assert_array_equal(got, est.estimate(pts, -1, b))   # deterministic


@pytest.mark.parametrize("bad", [0, 17, 2.5, True, "4"])
def test_bad_views_are_refused(bad):
    with pytest.raises(ValueError, match="views must be an integer in 1..16"):
        A3BoxNetEstimator(views=bad)
