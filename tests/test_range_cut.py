"""A body reaching past the depth sensor's range is boxed from the image (track3d.range_cut)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from track3d.boxes import box3d_from_points, iou_3d
from track3d.camera import Camera
from track3d.fusion import fuse
from track3d.range_cut import (CAP_FUSION_COVERAGE, CARRY_DEPTH_EXPONENT, CUT_RATIO_WEIGHT, DEPTH_RATIO, MIN_COVERAGE,
                               box_at_range, box_from_view, carry_box, cut_ratio, deepen_to_view, is_range_cut,
                               lateral_coverage, reaches_range)
from track3d.synthetic import CAM, render_sphere
from track3d.tracker import CARRY_SLIVER, NO_POINTS, TRACKING, Track3D
from track3d.trackers2d import OracleTracker

CAM100 = Camera.from_intrinsics(100, 100, 100.0, 100.0, 50.0, 50.0)


def test_box_from_view_hand_cases():
    # centred 20 x 20 px box, front face at 10 m, ratio 1: size z = 0.2 zc (0.2 = 20 px / 100 px
    # per unit), zc = 10 + 0.1 zc -> zc = 10 / 0.9
    zc = 10.0 / 0.9
    np.testing.assert_allclose(box_from_view(np.array([40.0, 40.0, 20.0, 20.0]), CAM100, 10.0),
                               [0.0, 0.0, zc, 0.2 * zc, 0.2 * zc, 0.2 * zc])
    # the box 20 px right of the centre: its centre on that ray; ratio 2 doubles size z
    zc2 = 10.0 / 0.8
    np.testing.assert_allclose(box_from_view(np.array([60.0, 40.0, 20.0, 20.0]), CAM100, 10.0, ratio=2.0),
                               [0.2 * zc2, 0.0, zc2, 0.2 * zc2, 0.2 * zc2, 0.4 * zc2])
    # a non-square box: size z is the mean of sizes x and y
    b = box_from_view(np.array([40.0, 45.0, 20.0, 10.0]), CAM100, 10.0)
    assert b[5] == pytest.approx((b[3] + b[4]) / 2) and b[2] - b[5] / 2 == pytest.approx(10.0)
    assert DEPTH_RATIO == 1.0
    # no box when the depth would not be positive (a box wider than twice the focal length)
    assert box_from_view(np.array([0.0, 0.0, 300.0, 300.0]), CAM100, 10.0) is None
    assert box_from_view(np.array([40.0, 40.0, 20.0, 20.0]), CAM100, 0.0) is None


def test_deepen_to_view_hand_cases():
    # the view of a centred 20 x 20 px box with its front face at 10 m reaches back to
    # 10 + 0.2 zc with zc = 10 / 0.9 (test above): 12.2222 m
    box2d, back = np.array([40.0, 40.0, 20.0, 20.0]), 10.0 + 0.2 * 10.0 / 0.9
    shallow = np.array([0.1, -0.2, 10.5, 2.0, 1.5, 1.0])        # front 10.0, back 11.0
    got = deepen_to_view(shallow, box2d, CAM100, 10.0)
    np.testing.assert_allclose(got, [0.1, -0.2, (10.0 + back) / 2, 2.0, 1.5, back - 10.0])
    assert shallow[5] == 1.0                                      # the input is not changed
    deep = np.array([0.0, 0.0, 11.5, 2.0, 2.0, 3.0])             # back 13.0: already deeper
    np.testing.assert_allclose(deepen_to_view(deep, box2d, CAM100, 10.0), deep)
    # the front face stays the box's own, only the back face moves
    late = np.array([0.0, 0.0, 10.75, 2.0, 2.0, 0.5])             # front 10.5, back 11.0
    g = deepen_to_view(late, box2d, CAM100, 10.0)
    assert g[2] - g[5] / 2 == pytest.approx(10.5) and g[2] + g[5] / 2 == pytest.approx(back)
    # no view (a box wider than twice the focal length): the box as it was
    np.testing.assert_allclose(deepen_to_view(shallow, np.array([0.0, 0.0, 300.0, 300.0]), CAM100, 10.0), shallow)


def test_coverage_and_cut_hand_cases():
    box = np.array([40.0, 40.0, 20.0, 20.0])            # 2 m x 2 m at 10 m
    full = np.array([[-1.0, -1.0, 10.0], [1.0, 1.0, 10.5]])
    half = np.array([[-0.5, -1.0, 10.0], [0.5, 1.0, 10.5]])
    assert lateral_coverage(full, box, CAM100) == pytest.approx(1.0)
    assert lateral_coverage(half, box, CAM100) == pytest.approx(0.5)
    assert MIN_COVERAGE == 0.9
    # the farthest return at the range: cut when the returns cover less of the box
    assert is_range_cut(half, box, CAM100, 10.5)
    assert not is_range_cut(full, box, CAM100, 10.5)            # the whole body is seen
    assert not is_range_cut(half, box, CAM100, 12.0)            # the returns stop short of the range
    assert not is_range_cut(half, box, CAM100, None)            # an unlimited sensor is never cut
    assert reaches_range(full, box, CAM100, 10.5) and reaches_range(half, box, CAM100, 10.5)
    assert not reaches_range(full, box, CAM100, 12.0) and not reaches_range(full, box, CAM100, None)
    # the range is along the ray: off-centre, the same range reaches less far in z
    off = np.array([80.0, 40.0, 20.0, 20.0])                      # centre ray (0.4, 0, 1)
    cap = np.array([[3.5, -1.0, 10.0], [4.5, 1.0, 10.5]])
    assert is_range_cut(cap, off, CAM100, 10.5 * np.sqrt(1.16))
    assert not is_range_cut(cap, off, CAM100, 10.5 * np.sqrt(1.16) * 1.05)


class _CapBox:
    """The visible points' bounding box: what an estimator shown a cap answers."""

    def estimate(self, points, category):
        return box3d_from_points(points)


def _cut_sphere(range_m: float, centre=(0.0, 0.0, 32.5), radius: float = 3.0):
    img, depth, b2, b3 = render_sphere(CAM, centre, radius)
    pts = CAM.backproject_depth(depth)
    return img, pts[np.linalg.norm(pts, axis=1) <= range_m], b2, b3


def test_the_loop_boxes_a_body_past_the_range_from_the_image():
    """A sphere of radius 3 m at 32.5 m behind a 30 m sensor range: the returns are its front
    cap. Told the range, the loop reports the box from the image (the cap's box without it);
    the cap covers about half of the 2D box, so the 2D box is not fused with it."""
    img, pts, b2, b3 = _cut_sphere(30.0)
    assert 0 < len(pts) and np.linalg.norm(pts, axis=1).max() <= 30.0
    gt2d = np.array([b2, b2])
    out = {}
    for rng in (None, 30.0):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng, silhouette=0.0)
        t.init(img, b2)
        r = t.update(img, pts)
        assert r.status == TRACKING
        out[rng] = r
        assert t.describe()["options"]["depth_range_m"] == rng
    # the returns' outline is the cap's: with the range known, the loop starts from the image's box
    t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, silhouette=0.5)
    t.init(img, b2)
    r = t.update(img, pts)
    np.testing.assert_array_equal(r.box3d, out[30.0].box3d)
    np.testing.assert_array_equal(r.box2d, out[30.0].box2d)
    cap = box3d_from_points(pts[(np.abs(pts[:, 0]) < 10)])
    np.testing.assert_allclose(out[None].box3d, cap)
    lo = pts.min(axis=0)
    np.testing.assert_allclose(out[30.0].box3d, box_from_view(b2, CAM, float(lo[2])))
    assert iou_3d(out[30.0].box3d, b3) > 0.6 > 0.3 > iou_3d(out[None].box3d, b3)
    # the cap is not the body's extent: told the range, the 2D tracker's box stands; not told,
    # the loop fuses the cap's box and shrinks it
    np.testing.assert_array_equal(out[30.0].box2d, b2)
    np.testing.assert_allclose(out[None].box2d, fuse(b2, cap, CAM, t.weight_3d))
    assert out[None].box2d[2] < b2[2] - 2
    # a body in range is the estimator's, range or not
    img, pts, b2, b3 = _cut_sphere(45.0)
    t = Track3D(CAM, OracleTracker(np.array([b2, b2])), _CapBox(), depth_range_m=45.0)
    t.init(img, b2)
    np.testing.assert_allclose(t.update(img, pts).box3d, box3d_from_points(pts))


@pytest.mark.parametrize("z, small", [(32.5, True), (31.8, False)])
def test_the_2d_box_is_fused_with_a_cap_only_when_the_cap_covers_enough_of_it(z, small):
    """A cap covering less than CAP_FUSION_COVERAGE of the 2D box (a sphere of radius 3 m at
    32.5 m behind a 30 m range, coverage ~0.55) leaves the 2D box to the tracker, frame after
    frame (fused, it shrank the box onto the cap: the 2D tracker is corrected with the fused
    box); a larger one (at 31.8 m, ~0.8, still cut) is fused with the estimator's box of it."""
    img, pts, b2, _ = _cut_sphere(30.0, centre=(0.0, 0.0, z))
    bounds = np.stack([pts.min(axis=0), pts.max(axis=0)])
    coverage = lateral_coverage(bounds, b2, CAM)
    assert is_range_cut(bounds, b2, CAM, 30.0) and (coverage < CAP_FUSION_COVERAGE) == small
    t = Track3D(CAM, OracleTracker(np.array([b2] * 4)), _CapBox(), depth_range_m=30.0, silhouette=0.0)
    t.init(img, b2)
    for _ in range(3):
        r = t.update(img, pts)
        assert r.status == TRACKING
        if small:
            np.testing.assert_array_equal(r.box2d, b2)
        else:
            np.testing.assert_allclose(r.box2d, fuse(b2, box3d_from_points(pts), CAM, t.weight_3d))


def test_a_body_reaching_the_range_with_its_outline_seen_keeps_a_deepened_box():
    """A sphere of radius 3 m at 31 m behind a 30 m range: only the rim near the limb is past the
    range, so the returns cover the outline (not cut) but stop at 30 m. The estimator shown that
    cloud answers a 2 m deep box; the loop pushes its back face to the image's box's (5.8 m
    deep), x / y and the front face its own."""
    img, pts, b2, b3 = _cut_sphere(30.0, centre=(0.0, 0.0, 31.0))
    bounds = np.stack([pts.min(axis=0), pts.max(axis=0)])
    assert reaches_range(bounds, b2, CAM, 30.0) and not is_range_cut(bounds, b2, CAM, 30.0)
    out = {}
    for rng in (None, 30.0):
        t = Track3D(CAM, OracleTracker(np.array([b2, b2])), _CapBox(), depth_range_m=rng, fusion=False)
        t.init(img, b2)
        out[rng] = t.update(img, pts).box3d
    view = box_from_view(b2, CAM, float(bounds[0, 2]))
    front = out[None][2] - out[None][5] / 2
    assert out[30.0][2] - out[30.0][5] / 2 == pytest.approx(front)
    assert out[30.0][2] + out[30.0][5] / 2 == pytest.approx(view[2] + view[5] / 2)
    np.testing.assert_allclose(out[30.0][[0, 1, 3, 4]], out[None][[0, 1, 3, 4]])
    assert iou_3d(out[30.0], b3) > 0.6 > 0.3 > iou_3d(out[None], b3)


def test_the_deepened_box_is_as_deep_for_its_width_as_the_bodys_last_box_within_range():
    """The same sphere first at 25 m (every return within the 30 m range: the estimator's box
    sets the body's depth-to-width ratio, checkpointed with the state), then at 31 m (the returns
    reach the range): the back face goes to that of the image's box at that ratio, not at 1."""
    img_n, pts_n, b2_n, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 25.0))
    img_f, pts_f, b2_f, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 31.0))
    t = Track3D(CAM, OracleTracker(np.array([b2_n, b2_n, b2_f])), _CapBox(), depth_range_m=30.0, fusion=False,
                depth_smoothing=0.0)
    t.init(img_n, b2_n)
    near = t.update(img_n, pts_n).box3d
    ratio = near[5] / ((near[3] + near[4]) / 2)
    assert 0.3 < ratio < 0.7                                       # a cap: about half as deep as wide
    assert t.get_state()["depth_ratio"] == pytest.approx(ratio)
    far = t.update(img_f, pts_f).box3d
    view = box_from_view(b2_f, CAM, float(pts_f[:, 2].min()), ratio=ratio)
    assert far[2] + far[5] / 2 == pytest.approx(view[2] + view[5] / 2)
    assert far[5] < box_from_view(b2_f, CAM, float(pts_f[:, 2].min()))[5]


def test_cut_ratio_hand_cases():
    assert CUT_RATIO_WEIGHT == 0.5
    assert cut_ratio(0.25) == pytest.approx(0.5)                  # sqrt(1 x 0.25)
    assert cut_ratio(1.69) == pytest.approx(1.3)
    assert cut_ratio(1.0) == DEPTH_RATIO
    assert cut_ratio(0.25, weight=0.0) == DEPTH_RATIO            # the old rule: ratio 1 always
    assert cut_ratio(0.25, weight=1.0) == pytest.approx(0.25)    # the body's own
    for none in (float("nan"), float("inf"), 0.0, -0.5):          # never seen within the range
        assert cut_ratio(none) == DEPTH_RATIO


def test_a_body_cut_by_the_range_keeps_between_ratio_1_and_its_own_last_ratio():
    """The sphere at 25 m (every return within the 30 m range: the estimator's box of the cap
    sets the body's depth-to-width ratio r, about 0.5), then at 32.5 m (cut: boxed from the
    image): the box is as deep for its width as sqrt(r), shallower than at ratio 1; a loop that
    never saw the body within the range boxes it at ratio 1 (the first test above)."""
    img_n, pts_n, b2_n, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 25.0))
    img_f, pts_f, b2_f, _ = _cut_sphere(30.0)
    t = Track3D(CAM, OracleTracker(np.array([b2_n, b2_n, b2_f])), _CapBox(), depth_range_m=30.0, fusion=False,
                silhouette=0.0, depth_smoothing=0.0)
    t.init(img_n, b2_n)
    near = t.update(img_n, pts_n).box3d
    r = near[5] / ((near[3] + near[4]) / 2)
    assert 0.3 < r < 0.7
    far = t.update(img_f, pts_f).box3d
    front = float(pts_f[:, 2].min())
    np.testing.assert_allclose(far, box_from_view(b2_f, CAM, front, ratio=np.sqrt(r)))
    assert far[5] < box_from_view(b2_f, CAM, front)[5]
    assert far[2] - far[5] / 2 == pytest.approx(front)


def test_a_view_cut_by_the_image_border_lends_no_depth_ratio():
    """The sphere at 25 m, half off the image's left border (the returns within the range, the
    box's width the part in view), then at 32.5 m (cut by the range): the border view sets no
    ratio, so the box from the image is at ratio 1, as for a body never seen whole."""
    img_b, pts_b, b2_b, _ = _cut_sphere(30.0, centre=(-14.0, 0.0, 25.0))
    img_f, pts_f, b2_f, _ = _cut_sphere(30.0)
    assert b2_b[0] <= 0.5 and len(pts_b) > 0 and np.linalg.norm(pts_b, axis=1).max() < 29.0
    t = Track3D(CAM, OracleTracker(np.array([b2_b, b2_b, b2_f])), _CapBox(), depth_range_m=30.0, fusion=False,
                silhouette=0.0, depth_smoothing=0.0)
    t.init(img_b, b2_b)
    assert t.update(img_b, pts_b).status == TRACKING
    assert t.get_state()["depth_ratio"] is None
    far = t.update(img_f, pts_f).box3d
    np.testing.assert_allclose(far, box_from_view(b2_f, CAM, float(pts_f[:, 2].min())))


def test_carry_box_hand_cases():
    """CAM100: fx = fy = 100, principal point (50, 50). A box on the optical axis at 20 m that
    went with a 20 x 20 px box centred on it; the new 2D box is 10 x 10 px centred at (65, 45):
    the rays' tangents are 0.15 and -0.05, the area ratio 4, so the depth goes to 20 * 2 **
    exponent and the centre onto the new ray; the size stays."""
    b3 = np.array([0.0, 0.0, 20.0, 2.0, 3.0, 4.0])
    last, new = np.array([40.0, 40.0, 20.0, 20.0]), np.array([60.0, 40.0, 10.0, 10.0])
    for e, z in ((0.0, 20.0), (0.5, 20.0 * np.sqrt(2.0)), (1.0, 40.0)):
        np.testing.assert_allclose(carry_box(b3, last, new, CAM100, e), [0.15 * z, -0.05 * z, z, 2.0, 3.0, 4.0])
    assert CARRY_DEPTH_EXPONENT == 0.5
    # an offset from the old ray is kept: a box 1 m right of it at 20 m (tangent 0.05) stays 0.05 right
    off = carry_box(b3 + [1.0, 0, 0, 0, 0, 0], last, new, CAM100, 1.0)
    np.testing.assert_allclose(off[:3], [(0.15 + 0.05) * 40.0, -0.05 * 40.0, 40.0])
    # the same 2D box: unchanged; a box that is not finite or a 2D box of no size: a copy, unchanged
    np.testing.assert_allclose(carry_box(b3, last, last, CAM100), b3)
    nan = np.full(6, np.nan)
    assert np.all(np.isnan(carry_box(nan, last, new, CAM100)))
    np.testing.assert_array_equal(carry_box(b3, last, [60.0, 40.0, 0.0, 10.0], CAM100), b3)


def test_carry_box_at_the_image_border_hand_cases():
    """CAM100 (fx = fy = 100, 100 x 100 px). A box at 20 m with a 20 x 20 px box at (40, 40); the
    new box is cut by the right border, [70, 30, 30, 20]: its left side moved 30 px (0.3 m per m
    of depth: 6 m at 20 m), its centre in y 10 px up (-2 m); the depth and size stay."""
    b3 = np.array([0.0, 0.0, 20.0, 2.0, 3.0, 4.0])
    last, cut = np.array([40.0, 40.0, 20.0, 20.0]), np.array([70.0, 30.0, 30.0, 20.0])
    right = (False, False, True, False)
    np.testing.assert_allclose(carry_box(b3, last, cut, CAM100, 1.0, (False,) * 4, right), [6.0, -2.0, 20.0, 2.0, 3.0, 4.0])
    # from a box cut on the right to one cut on the right: the left sides (70 -> 80: +2 m)
    np.testing.assert_allclose(carry_box(b3, cut, [80.0, 30.0, 20.0, 20.0], CAM100, 1.0, right, right),
                               [2.0, 0.0, 20.0, 2.0, 3.0, 4.0])
    # cut on the left (x = 0): its right side; both sides at the border in y: no move in y
    tall = (True, True, False, True)
    np.testing.assert_allclose(carry_box(b3, [0.0, 0.0, 30.0, 100.0], [0.0, 0.0, 20.0, 100.0], CAM100, 1.0, tall, tall),
                               [-2.0, 0.0, 20.0, 2.0, 3.0, 4.0])
    # no side at the border: the clear rule, as without sides
    np.testing.assert_array_equal(carry_box(b3, last, cut, CAM100, 1.0, (False,) * 4, (False,) * 4),
                                  carry_box(b3, last, cut, CAM100, 1.0))
    # from the cut box to a clear 10 x 10 px box at (40, 40): across the line of sight by the
    # left sides (-30 px: -6 m) and the centres in y (+5 px: +1 m) at 20 m, the depth kept...
    clear = np.array([40.0, 40.0, 10.0, 10.0])
    np.testing.assert_allclose(carry_box(b3, cut, clear, CAM100, 1.0, right, (False,) * 4),
                               [-6.0, 1.0, 20.0, 2.0, 3.0, 4.0])
    # ... unless the body's last clear 2D box is known. To a clear 30 x 30 px box at (40, 40): -6 m
    # and +3 m across at 20 m; 3600 px^2 at 10 m is 30 x 30 px at the cut box's 20 m, the new box's
    # size: the depth stays; 900 px^2 at 40 m is 60 x 60 px at 20 m, twice the new box's side: the
    # depth doubles (exponent 1) along the moved centre's ray
    big = np.array([40.0, 40.0, 30.0, 30.0])
    np.testing.assert_allclose(carry_box(b3, cut, big, CAM100, 1.0, right, (False,) * 4, last_whole=(3600.0, 10.0)),
                               [-6.0, 3.0, 20.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(carry_box(b3, cut, big, CAM100, 1.0, right, (False,) * 4, last_whole=(900.0, 40.0)),
                               [-12.0, 6.0, 40.0, 2.0, 3.0, 4.0])
    # a cut box larger than the clear one's size there (100 px^2 at 20 m: 10 px; the cut box's
    # sqrt(30 x 20) = 24.5 px) is the body's size: the depth goes as 24.5 / 30
    np.testing.assert_allclose(carry_box(b3, cut, big, CAM100, 1.0, right, (False,) * 4, last_whole=(100.0, 20.0))[2],
                               20.0 * np.sqrt(600.0) / 30.0)
    # a box at the border now, or no clear box known (nan): the depth kept
    for sides, whole in ((right, (900.0, 40.0)), ((False,) * 4, (float("nan"), float("nan")))):
        assert carry_box(b3, cut, big, CAM100, 1.0, right, sides, last_whole=whole)[2] == 20.0


def test_a_body_past_the_range_at_the_image_border_follows_the_side_in_view():
    """A sphere of radius 3 m at 31 m (its returns reach the 30 m range), then wholly past the
    range at 34 m sliding off the right border (18 m, then 19.5 m to the side: 2D boxes cut by the
    border, no return), then back in view at 2 m. At the border the 3D box follows the 2D box's
    left side at the same depth (before: held at the first frame's, 18 m behind the body); back in
    view it is carried from the last clear pair, as a body that had never been at the border. A
    checkpoint at the border continues bit-identically."""
    frames = [_cut_sphere(30.0, centre=c) for c in ((0.0, 0.0, 31.0), (18.0, 0.0, 34.0), (19.5, 0.0, 34.0),
                                                   (2.0, 0.0, 34.0))]
    (img1, pts1, b2_1, _), (img2, pts2, b2_2, b3_2), (img3, pts3, b2_3, b3_3), (img4, pts4, b2_4, b3_4) = frames
    assert len(pts1) > 100 and len(pts2) == len(pts3) == len(pts4) == 0
    assert b2_2[0] + b2_2[2] >= CAM.width - 0.5 and b2_3[0] + b2_3[2] >= CAM.width - 0.5
    gt2d = np.array([b2_1, b2_1, b2_2, b2_3, b2_4])

    def run(restore: bool):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, fusion=False)
        t.init(img1, b2_1)
        out = [t.update(img1, pts1), t.update(img2, pts2)]
        if restore:
            t2 = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, fusion=False)
            t2.set_state(json.loads(json.dumps(t.get_state())))
            t = t2
        return out + [t.update(img3, pts3), t.update(img4, pts4)]

    r1, r2, r3, r4 = run(False)
    assert (r1.status, r2.status, r3.status, r4.status) == (TRACKING, NO_POINTS, NO_POINTS, NO_POINTS)
    right, clear = (False, False, True, False), (False,) * 4
    np.testing.assert_allclose(r2.box3d, carry_box(r1.box3d, b2_1, b2_2, CAM, last_sides=clear, sides=right))
    np.testing.assert_allclose(r3.box3d, carry_box(r2.box3d, b2_2, b2_3, CAM, last_sides=right, sides=right))
    # within the carried box's depth error (its cap-made box lies 3 m near: 0.9 of the shift)
    assert r2.box3d[2] == r1.box3d[2] and abs(r2.box3d[0] - b3_2[0]) < 2.0 and abs(r1.box3d[0] - b3_2[0]) > 15.0
    assert abs(r3.box3d[0] - b3_3[0]) < 2.5
    np.testing.assert_allclose(r4.box3d, carry_box(r1.box3d, b2_1, b2_4, CAM))
    for a, b in zip(run(True), (r1, r2, r3, r4)):
        np.testing.assert_array_equal(a.box3d, b.box3d)


def test_a_body_past_the_range_is_carried_by_the_image_box():
    """A sphere of radius 3 m at 31 m (its returns reach the 30 m range), then at 34 m and 1.5 m
    to the side (no return at all): the frame is "no_points" and the 3D box follows the 2D box, by
    carry_box from the box of the last estimate; a checkpoint taken between the two frames
    continues bit-identically. Without the range, or with the body's returns last within the
    range, the box is held as it was."""
    img1, pts1, b2_1, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 31.0))
    img2, pts2, b2_2, b3_2 = _cut_sphere(30.0, centre=(1.5, 0.0, 34.0))
    assert len(pts1) > 100 and len(pts2) == 0
    gt2d = np.array([b2_1, b2_1, b2_2])

    def run(rng, first=(img1, pts1), restore=False):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng, fusion=False)
        t.init(first[0], b2_1)
        r1 = t.update(*first)
        if restore:
            state = t.get_state()
            t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng, fusion=False)
            t.set_state(state)
        return r1, t.update(img2, pts2)

    r1, r2 = run(30.0)
    assert r1.status == TRACKING and r2.status == NO_POINTS
    np.testing.assert_allclose(r2.box3d, carry_box(r1.box3d, b2_1, b2_2, CAM))
    # nearer the body than the held box: across the line of sight and (damped) along it
    err = lambda b: np.abs(b[:3] - b3_2[:3])
    assert np.all(err(r2.box3d)[[0, 2]] < err(r1.box3d)[[0, 2]] - 0.5) and iou_3d(r2.box3d, b3_2) > iou_3d(r1.box3d, b3_2)
    np.testing.assert_array_equal(run(30.0, restore=True)[1].box3d, r2.box3d)
    held = run(None)
    np.testing.assert_array_equal(held[1].box3d, held[0].box3d)
    img0, pts0, _, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 20.0))   # last estimate within the range
    near = run(30.0, first=(img0, pts0))
    np.testing.assert_array_equal(near[1].box3d, near[0].box3d)


@pytest.mark.parametrize("x, sliver", [(17.0, True), (15.5, False)])
def test_a_body_past_the_range_is_carried_from_its_last_clear_view_not_from_a_sliver_at_the_border(x, sliver):
    """A sphere whole in view whose returns reach the 30 m range (a 26 x 26 px box), then at the
    image border (returns still reaching the range), then back in view wholly past it. A border
    box with less than CARRY_SLIVER of the clear box's area (9 x 26 px) is a sliver: the box is
    carried from the clear view's pair (carried from the sliver it came out 8.5 m too near; a
    README ToF long watch's held-out 0008 lost 8 m the same way). A border box about the body's
    size (16 x 32 px, as SiamFC's keeps its size at the border) is the latest pair and carried
    from, across the line of sight by its side in view and in depth as from a clear box of the size
    the body would have had there (the clear box's, by its depth over the pair's; the cut box's own
    size had put it 6.6 m too near, now 4.3 m, CARRY_CUT_FROM_CLEAR). A checkpoint at the border frame keeps
    the choice."""
    img1, pts1, b2_1, _ = _cut_sphere(30.0, centre=(0.0, 0.0, 31.0))
    img2, pts2, b2_2, _ = _cut_sphere(30.0, centre=(x, 0.0, 26.5))
    img3, pts3, b2_3, b3_3 = _cut_sphere(30.0, centre=(-1.5, 0.0, 34.0))
    assert b2_2[0] + b2_2[2] >= CAM.width - 0.5 and len(pts2) > 100 and len(pts3) == 0
    assert (b2_2[2] * b2_2[3] < CARRY_SLIVER * b2_1[2] * b2_1[3]) == sliver
    gt2d = np.array([b2_1, b2_1, b2_2, b2_3])

    def run(restore: bool):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, fusion=False)
        t.init(img1, b2_1)
        r1, r2 = t.update(img1, pts1), t.update(img2, pts2)
        if restore:
            t2 = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, fusion=False)
            t2.set_state(json.loads(json.dumps(t.get_state())))
            t = t2
        return r1, r2, t.update(img3, pts3)

    r1, r2, r3 = run(False)
    assert (r1.status, r2.status, r3.status) == (TRACKING, TRACKING, NO_POINTS)
    assert reaches_range(np.array([pts2.min(0), pts2.max(0)]), b2_2, CAM, 30.0)   # the border view reached it too
    right = (False, False, True, False)
    from_clear = carry_box(r1.box3d, b2_1, b2_3, CAM)
    from_border = carry_box(r2.box3d, b2_2, b2_3, CAM, last_sides=right, last_whole=(b2_1[2] * b2_1[3], r1.box3d[2]))
    np.testing.assert_allclose(r3.box3d, from_clear if sliver else from_border)
    by_cut_size = carry_box(r2.box3d, b2_2, b2_3, CAM)   # the cut box's size taken for the body's
    if sliver:
        assert abs(r3.box3d[2] - b3_3[2]) < 2.0 < abs(by_cut_size[2] - b3_3[2])
    else:   # 4.3 m near (the pair's cap-made box is 3 m near and the depth's change damped) for 6.6
        assert abs(r3.box3d[2] - b3_3[2]) + 2.0 < abs(by_cut_size[2] - b3_3[2])
    np.testing.assert_array_equal(run(True)[2].box3d, r3.box3d)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan"), float("inf")])
def test_a_range_that_is_not_a_positive_distance_is_refused(bad):
    with pytest.raises(ValueError, match="depth_range_m"):
        Track3D(CAM, OracleTracker(np.zeros((1, 4))), _CapBox(), depth_range_m=bad)


def test_the_evaluation_tells_the_loop_its_sensors_range(tmp_path):
    from track3d.dataset import Dataset
    from track3d.evaluation import TrackerSpec
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "d", {"a": 4, "b": 4, "c": 4})
    for name, sensor in (("b", {"name": "tof", "max_range_m": 30.0}), ("c", {"name": "tof", "max_range_m": "far"})):
        meta = root / "test" / name / "meta.json"
        m = json.loads(meta.read_text())
        m["depth_sensor"] = sensor
        meta.write_text(json.dumps(m))
    a, b, c = Dataset(root).sequences("test")
    assert (a.depth_range_m, b.depth_range_m, c.depth_range_m) == (None, 30.0, None)
    assert TrackerSpec("oracle", "baseline").build(b).depth_range_m == 30.0
    assert TrackerSpec("oracle", "baseline", depth_range=False).build(b).depth_range_m is None
    assert TrackerSpec("oracle", "baseline").build(a).depth_range_m is None


def test_track_cli_uses_the_recorded_range_and_the_measured_faces_unless_told_not_to(tmp_path, capsys):
    from track3d.cli import main
    from track3d.evaluation.results import read_run_record
    from track3d.synthetic import make_synthetic_dataset

    root = make_synthetic_dataset(tmp_path / "d", {"a": 4})
    meta = root / "test" / "a" / "meta.json"
    m = json.loads(meta.read_text())
    m["depth_sensor"] = {"name": "tof", "max_range_m": 30.0}
    meta.write_text(json.dumps(m))
    res = tmp_path / "res"
    assert main(["track", "--data", str(root), "--tracker", "oracle", "--results", str(res), "--quiet"]) == 0
    assert main(["track", "--data", str(root), "--tracker", "oracle", "--results", str(res), "--quiet",
                 "--no-depth-range", "--name", "norange"]) == 0
    assert main(["track", "--data", str(root), "--tracker", "oracle", "--results", str(res), "--quiet",
                 "--no-measured-faces", "--name", "nofront"]) == 0
    rec = read_run_record(res, "test", "oracle+a3boxnet")   # the default estimator
    assert rec["track3d"]["options"]["depth_range_m"] == 30.0 and rec["track3d"]["options"]["measured_faces"] is True
    assert read_run_record(res, "test", "norange")["track3d"]["options"]["depth_range_m"] is None
    assert read_run_record(res, "test", "nofront")["track3d"]["options"]["measured_faces"] is False


def test_box_at_range_hand_cases():
    # a centred 20 x 20 px box: the centre ray is the optical axis, the front face at the range
    zc = 30.0 / 0.9
    np.testing.assert_allclose(box_at_range(np.array([40.0, 40.0, 20.0, 20.0]), CAM100, 30.0),
                               [0.0, 0.0, zc, 0.2 * zc, 0.2 * zc, 0.2 * zc])
    # 50 px right of the centre (ray x / z = 0.5): the front face's centre 30 m away along the ray
    b = box_at_range(np.array([90.0, 40.0, 20.0, 20.0]), CAM100, 30.0)
    front = 30.0 / np.sqrt(1.25)
    np.testing.assert_allclose(b, box_from_view(np.array([90.0, 40.0, 20.0, 20.0]), CAM100, front))
    assert np.linalg.norm([b[0] / b[2] * front, 0.0, front]) == pytest.approx(30.0)
    assert box_at_range(np.array([0.0, 0.0, 300.0, 300.0]), CAM100, 30.0) is None


def test_a_body_past_the_range_from_the_first_frame_is_boxed_at_the_range_and_carried():
    """A sphere of radius 3 m at 34 m behind a 30 m range: no return in the first frame's box, nor
    after. It had no 3D box at all (NaN every frame); now the first box is box_at_range, then
    carried by the 2D box (status "no_points"); a checkpoint continues bit-identically. Without a
    range nothing is guessed; the first returns replace the guess."""
    img1, pts1, b2_1, b3_1 = _cut_sphere(30.0, centre=(0.0, 0.0, 34.0))
    img2, pts2, b2_2, b3_2 = _cut_sphere(30.0, centre=(1.0, 0.0, 33.5))
    assert len(pts1) == 0 and len(pts2) == 0
    gt2d = np.array([b2_1, b2_2])

    def run(rng, restore=False, frames=((None, None),)):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng, fusion=False)
        t.init(img1, b2_1, points=pts1)
        first = t.box3d.copy()
        if restore:
            state = t.get_state()
            t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng, fusion=False)
            t.set_state(state)
        return first, [t.update(img, pts) for img, pts in ((img2, pts2),) + tuple(f for f in frames if f[0] is not None)]

    first, (r2,) = run(30.0)
    np.testing.assert_allclose(first, box_at_range(b2_1, CAM, 30.0))
    assert iou_3d(first, b3_1) > 0.3
    assert r2.status == NO_POINTS
    np.testing.assert_allclose(r2.box3d, carry_box(first, b2_1, b2_2, CAM))
    np.testing.assert_array_equal(run(30.0, restore=True)[1][0].box3d, r2.box3d)
    none_first, (none2,) = run(None)
    assert np.all(np.isnan(none_first)) and np.all(np.isnan(none2.box3d))
    # a known first 3D box (--init-3d) is what is carried, not the guess at the range
    t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=30.0, fusion=False)
    t.init(img1, b2_1, points=pts1, box3d=b3_1)
    np.testing.assert_allclose(t.update(img2, pts2).box3d, carry_box(b3_1, b2_1, b2_2, CAM))
    # the body comes within the range: its returns' estimate replaces the guess
    img3, pts3, b2_3, _ = _cut_sphere(30.0, centre=(1.0, 0.0, 31.0))
    assert len(pts3) > 100
    gt2d = np.array([b2_1, b2_2, b2_3])
    _, (_, r3) = run(30.0, frames=((img3, pts3),))
    assert r3.status == TRACKING and r3.box3d[2] - r3.box3d[5] / 2 == pytest.approx(pts3[:, 2].min(), abs=0.3)
