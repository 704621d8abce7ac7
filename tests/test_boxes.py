import numpy as np
import pytest

from track3d import boxes as B


def test_iou_2d_hand_cases():
    assert B.iou_2d([0, 0, 10, 10], [0, 0, 10, 10]) == pytest.approx(1.0)
    assert B.iou_2d([0, 0, 10, 10], [5, 0, 10, 10]) == pytest.approx(50 / 150)
    assert B.iou_2d([0, 0, 10, 10], [10, 0, 10, 10]) == 0.0  # touching: no overlap
    assert B.iou_2d([0, 0, 10, 10], [0, 0, 0, 10]) == 0.0  # degenerate
    assert B.iou_2d([0, 0, 10, 10], [np.nan, 0, 5, 5]) == 0.0
    np.testing.assert_allclose(B.iou_2d(np.zeros((3, 4)) + [0, 0, 2, 2], [1, 1, 2, 2]), [1 / 7] * 3)


def test_iou_3d_and_bev_hand_cases():
    a = np.array([0, 0, 10, 2, 2, 2.0])
    b = np.array([1, 0, 10, 2, 2, 2.0])  # shifted 1 m along x: half overlap
    assert B.iou_3d(a, b) == pytest.approx(4 / 12)
    assert B.iou_bev(a, b) == pytest.approx(2 / 6)
    c = np.array([0, 5, 10, 2, 2, 2.0])  # shifted along y only: BEV identical, 3D disjoint
    assert B.iou_3d(a, c) == 0.0
    assert B.iou_bev(a, c) == pytest.approx(1.0)
    assert B.iou_3d(a, a) == pytest.approx(1.0)
    np.testing.assert_allclose(B.box3d_to_bev(a), [0, 10, 2, 2])


@pytest.mark.parametrize("bad", [[0, np.nan, 10, 2, 2, 2], [0, 0, 10, 2, np.nan, 2], [0, 0, 10, 2, 0, 2],
                                 [0, 0, 10, 2, -1, 2], [0, 0, 10, 2, np.inf, 2], [0, np.inf, 10, 2, 2, 2]])
def test_bev_iou_of_a_box_broken_in_y_is_zero(bad):
    """A result row with a NaN / zero / negative height scored BEV IoU 1 (only x and z were read)
    while its 3D IoU was 0 (a metrics review): not a box, IoU 0 with everything, as in 2D and 3D."""
    good = np.array([0, 0, 10, 2, 2, 2.0])
    assert B.iou_bev(bad, good) == 0.0 and B.iou_bev(good, bad) == 0.0
    assert B.iou_3d(bad, good) == 0.0
    np.testing.assert_allclose(B.iou_bev(np.stack([good, np.array(bad, float)]), good), [1.0, 0.0])


def test_center_errors():
    assert B.center_error_2d([0, 0, 2, 2], [3, 4, 2, 2]) == pytest.approx(5.0)
    assert B.center_error_3d([0, 0, 0, 1, 1, 1], [1, 2, 2, 5, 5, 5]) == pytest.approx(3.0)


def test_size_templates_are_table1():
    assert B.SIZE_TEMPLATES.shape == (14, 3)
    np.testing.assert_allclose(B.SIZE_TEMPLATES[2], [1 / 3, 1, 1])
    np.testing.assert_allclose(B.SIZE_TEMPLATES[13], [1, 2 / 3, 2 / 3])


def test_size_class_coding_roundtrip():
    cls, res = B.size_class_of(np.array([2.0, 4.0, 4.1]))
    # ratio (0.4878, 0.9756, 1): nearest template is class 1 (1/2, 1, 1)
    assert cls == 1
    np.testing.assert_allclose(res, np.array([2, 4, 4.1]) / 4.1 - [0.5, 1, 1])
    np.testing.assert_allclose(B.decode_size(cls, res, 4.1), [2.0, 4.0, 4.1])
    rng = np.random.default_rng(1)
    sizes = rng.uniform(1, 12, size=(100, 3))
    c, r = B.size_class_of(sizes)
    np.testing.assert_allclose(B.decode_size(c, r, sizes.max(1)), sizes)
    with pytest.raises(ValueError):
        B.size_class_of([0, 0, 0])


def test_min_enclosing_box():
    pts = np.array([[0, 0, 1], [2, 4, 3], [1, 1, 2.0]])
    np.testing.assert_allclose(B.box3d_from_points(pts), [1, 2, 2, 2, 4, 2])
    with pytest.raises(ValueError):
        B.box3d_from_points(np.zeros((0, 3)))


def test_clip_box2d():
    np.testing.assert_allclose(B.clip_box2d([-5, -5, 10, 10], 100, 100), [0, 0, 5, 5])
    np.testing.assert_allclose(B.clip_box2d([200, 0, 10, 10], 100, 100)[2], 0)
