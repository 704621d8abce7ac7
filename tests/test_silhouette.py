"""The body's outline from the depth returns (track3d.silhouette) and its use in the loop."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxes import iou_2d
from track3d.camera import Camera
from track3d.silhouette import silhouette_box

CAM = Camera.from_fov(160, 120, 45.0)


def _cloud(mask: np.ndarray, z: float = 10.0) -> np.ndarray:
    """(n, 3) float32 returns of the pixels set in `mask` (H, W), at depth z to z + 0.2 (a surface,
    not a plane: a box estimator needs some depth)."""
    rows, cols = np.indices(mask.shape)
    depth = np.where(mask, z + 0.05 * ((rows + cols) % 5), 0.0).astype(np.float32)
    return CAM.backproject_depth(depth)


def _answering(box):
    """A 2D tracker class whose every update answers `box`."""
    class Fixed:
        def init(self, image, box):
            pass

        def update(self, image):
            return True, np.array(answer, dtype=np.float64)
    answer = list(box)
    return Fixed


def _losing(box):
    """A 2D tracker class that judges its loss and calls every frame lost at `box`, recording
    the box the loop corrects it onto (None: not corrected)."""
    class Losing:
        lost = False
        corrected = None

        def init(self, image, box):
            pass

        def update(self, image):
            self.lost = True
            return False, np.array(answer, dtype=np.float64)

        def correct(self, box):
            self.corrected = np.array(box, dtype=np.float64)
    answer = list(box)
    return Losing


def _box(points, box, grow=0.5):
    return silhouette_box(points, np.asarray(box, float), CAM.M, (CAM.width, CAM.height), (0.1, 100.0), grow)[0]


def test_a_body_wider_than_the_box_is_found_whole():
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:110] = True            # the body: pixels x 30..109, y 40..69
    pts = _cloud(mask)
    # the tracker boxed its left half: the outline is the whole body (pixel edges)
    np.testing.assert_allclose(_box(pts, [30, 40, 40, 30], grow=1.0), [30, 40, 80, 30], atol=1e-3)
    # the first search region (the box grown by half its size on each side: x 10..90) cut it at
    # x 90; the outline reached that edge, so the region grew past it and the body came whole
    np.testing.assert_allclose(_box(pts, [30, 40, 40, 30]), [30, 40, 80, 30], atol=1e-3)
    # a box off the body: nothing overlaps it, the caller keeps its box
    assert _box(pts, [130, 90, 10, 10], grow=0.2) is None


def _regrown(points, box, grow=0.5, regrow=3):
    return silhouette_box(points, np.asarray(box, float), CAM.M, (CAM.width, CAM.height), (0.1, 100.0), grow,
                          regrow)


def test_an_outline_cut_by_the_search_region_is_searched_again_past_it():
    """A tracker that jumped off a large body overlapped only its top (a flash-LiDAR long watch,
    EdgeTrack drawn to a galaxy band): the outline stopped at the search region's edge."""
    mask = np.zeros((120, 160), bool)
    mask[30:100, 40:100] = True            # a tall body: pixels x 40..99, y 30..99
    pts = _cloud(mask)
    top = [45, 10, 50, 31]                 # overlaps rows 30..40 only; region y 0..56.5
    box, _, region = _regrown(pts, top, regrow=0)
    np.testing.assert_allclose(box, [40, 30, 60, 26], atol=1e-3)     # rows to 55: cut by the region
    np.testing.assert_allclose(region, [20, 0, 100, 56.5], atol=1e-3)
    # one regrowth: the region's bottom to 56 + 0.5 * 26 = 69, still cut (rows to 68); the third
    # reaches the body's end
    box, near, region = _regrown(pts, top, regrow=1)
    np.testing.assert_allclose(box, [40, 30, 60, 39], atol=1e-3)
    box, near, region = _regrown(pts, top)
    np.testing.assert_allclose(box, [40, 30, 60, 70], atol=1e-3)
    assert region[1] + region[3] >= 100 and len(near) == mask.sum()   # the points of the last region
    # a body that ends inside the first region is read once: the same as without regrowth
    small = np.zeros((120, 160), bool)
    small[30:50, 40:100] = True
    for k in (0, 3):
        np.testing.assert_allclose(_regrown(_cloud(small), top, regrow=k)[0], [40, 30, 60, 20], atol=1e-3)
    # the image border is not a cut: a body running off the bottom grows no region past it
    low = np.zeros((120, 160), bool)
    low[60:120, 40:100] = True
    box, _, region = _regrown(_cloud(low), [45, 70, 50, 40])
    np.testing.assert_allclose(box, [40, 60, 60, 60], atol=1e-3)
    np.testing.assert_allclose(region, [20, 50, 100, 70], atol=1e-3)


def test_a_separate_speck_is_left_out_and_a_sparse_grid_is_one_body():
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:90] = True
    mask[45:51, 100:106] = True           # 6 x 6 returns apart from the body, inside the search region
    np.testing.assert_allclose(_box(_cloud(mask), [40, 42, 50, 26]), [30, 40, 60, 30], atol=1e-3)
    # a box holding a fair share of both (16% of its occupied cells the speck's): two parts, the
    # body's whole (the first region, x 65..125, cut it; the second reaches its left end)
    np.testing.assert_allclose(_box(_cloud(mask), [80, 40, 30, 30]), [30, 40, 76, 30], atol=1e-3)
    # a flash LiDAR's returns every 4 pixels read as one body (centres x 30..106, y 40..68)
    sparse = np.zeros((120, 160), bool)
    sparse[40:70:4, 30:110:4] = True
    np.testing.assert_allclose(_box(_cloud(sparse), [30, 40, 40, 30], grow=1.0), [30, 40, 77, 29], atol=1e-3)


def test_returns_at_the_image_border_put_the_box_there():
    mask = np.zeros((120, 160), bool)
    mask[40:70, 2:60:4] = True            # a coarse grid's first column 2 px inside the border
    np.testing.assert_allclose(_box(_cloud(mask), [10, 40, 30, 30], grow=1.0), [0, 40, 59, 30], atol=1e-3)


def test_the_loop_reports_the_outline_not_the_trackers_half():
    """A 2D tracker boxing part of the body (a bilobate body's one lobe) kept the loop's box on that
    part: the frustum, the measured faces and the fusion all started from it."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    Half = _answering([30.0, 40.0, 40.0, 30.0])   # the left half of the body
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:110] = True
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    truth = np.array([[30.0, 40.0, 80.0, 30.0]])
    boxes = {}
    for grow in (0.0, 1.0):
        t = Track3D(CAM, Half(), create_estimator("baseline"), silhouette=grow)
        t.init(image, [30, 40, 80, 30], points=pts)
        boxes[grow] = t.update(image, pts).box2d
    assert iou_2d(boxes[1.0][None], truth)[0] > 0.98 > 0.8 > iou_2d(boxes[0.0][None], truth)[0]
    # without fusion the reported 2D box stays the tracker's own (the "2D alone" rows of Table 2
    # scored the outline: AO_2d 1.000)
    t = Track3D(CAM, Half(), create_estimator("baseline"), silhouette=1.0, fusion=False)
    t.init(image, [30, 40, 80, 30], points=pts)
    np.testing.assert_array_equal(t.update(image, pts).box2d, [30.0, 40.0, 40.0, 30.0])


def test_the_silhouette_option_is_checked_recorded_and_by_sensor(tmp_path):
    from track3d.estimators import create_estimator
    from track3d.evaluation import TrackerSpec
    from track3d.tracker import Track3D
    from track3d.sensor_options import SILHOUETTE, sensor_options, silhouette_for
    from track3d.trackers2d import create_tracker

    assert (silhouette_for("ideal") == silhouette_for("flash-lidar") == silhouette_for("ToF") == silhouette_for(None)
            == SILHOUETTE == 0.5)
    assert silhouette_for("stereo") == 0.0 and sensor_options("stereo")["silhouette"] == 0.0
    for bad in (-0.1, 5.0, float("nan")):
        with pytest.raises(ValueError, match="silhouette must be in"):
            Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), silhouette=bad)
    t = Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), silhouette=0.25)
    assert t.describe()["options"]["silhouette"] == 0.25
    from test_loop import _plain_and
    a, b = _plain_and(tmp_path, {"name": "stereo"})
    spec = TrackerSpec("oracle", "baseline")
    assert spec.build(a).silhouette == 0.5 and spec.build(b).silhouette == 0.0
    assert TrackerSpec("oracle", "baseline", silhouette=1.0).build(b).silhouette == 1.0


def test_the_outline_share_pulls_only_the_2d_fusions_box():
    """With the outline off (stereo), a share of it still corrects a 2D box grown past the body
    (EdgeTrack's box 207 px tall on a 127 px body, a stereo sequence); the frustum and so the
    3D box keep the tracker's box."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    Tall = _answering([30.0, 25.0, 80.0, 60.0])   # rows 25..85 around a body of rows 40..70
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:110] = True                    # the outline: [30, 40, 80, 30]
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    res = {}
    for share in (0.0, 0.3, 1.0):
        t = Track3D(CAM, Tall(), create_estimator("baseline"), silhouette=0.0, outline_share=share, weight_3d=0.0)
        t.init(image, [30, 40, 80, 30], points=pts)
        res[share] = t.update(image, pts)
    np.testing.assert_allclose(res[0.0].box2d, [30.0, 25.0, 80.0, 60.0], atol=1e-9)
    # 0.3 * [30, 40, 80, 30] + 0.7 * [30, 25, 80, 60], by hand
    np.testing.assert_allclose(res[0.3].box2d, [30.0, 29.5, 80.0, 51.0], atol=1e-3)
    np.testing.assert_allclose(res[1.0].box2d, [30.0, 40.0, 80.0, 30.0], atol=1e-3)
    np.testing.assert_array_equal(res[0.3].box3d, res[0.0].box3d)
    # with the outline on, the share has nothing to add: the outline is the box already
    a, b = (Track3D(CAM, Tall(), create_estimator("baseline"), silhouette=0.5, outline_share=s, weight_3d=0.0)
            for s in (0.0, 0.3))
    for t in (a, b):
        t.init(image, [30, 40, 80, 30], points=pts)
    np.testing.assert_array_equal(a.update(image, pts).box2d, b.update(image, pts).box2d)


def test_the_outline_share_option_is_checked_recorded_and_by_sensor(tmp_path):
    from track3d.estimators import create_estimator
    from track3d.evaluation import TrackerSpec
    from track3d.tracker import Track3D
    from track3d.sensor_options import outline_share_for, sensor_options
    from track3d.trackers2d import create_tracker

    assert outline_share_for("stereo") == 0.3 and sensor_options("stereo")["outline_share"] == 0.3
    assert outline_share_for("ideal") == outline_share_for("ToF") == outline_share_for(None) == 0.0
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="outline_share must be in"):
            Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), outline_share=bad)
    t = Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), outline_share=0.25)
    assert t.describe()["options"]["outline_share"] == 0.25
    from test_loop import _plain_and
    a, b = _plain_and(tmp_path, {"name": "tof", "max_range_m": 30.0})
    assert TrackerSpec("oracle", "baseline").build(b).outline_share == 0.0
    assert TrackerSpec("oracle", "baseline", outline_share=0.5).build(b).outline_share == 0.5


def test_contain_hand_cases():
    """The box moved the least, its size kept, to hold the outline (by hand, per axis)."""
    from track3d.silhouette import contain

    out = [30.0, 40.0, 80.0, 30.0]                        # x 30..110, y 40..70
    # a box of the outline's size 10 px right and 15 px low of it: moved onto it
    np.testing.assert_array_equal(contain([40, 55, 80, 30], out), out)
    # a larger box (the dark side) holding the outline: left as it is
    np.testing.assert_array_equal(contain([20, 30, 120, 60], out), [20, 30, 120, 60])
    # a larger box beside it: shifted by what the outline passes it, its size kept
    # x: 40..160 -> 30..150; y: 20..65 -> 25..70
    np.testing.assert_array_equal(contain([40, 20, 120, 45], out), [30, 25, 120, 45])
    # a smaller box: moved to the low side, then grown to the high side
    # x: 50..70 -> 30..110; y: 60..65 -> 40..70
    np.testing.assert_array_equal(contain([50, 60, 20, 5], out), out)
    # slack 2: the outline shrunk to x 32..108, y 42..68 before it is held
    # x: 40..120 -> 32..112; y: 55..85 -> 42..72
    np.testing.assert_array_equal(contain([40, 55, 80, 30], out, 2.0), [32, 42, 80, 30])
    np.testing.assert_array_equal(contain([31, 39, 80, 30], out, 2.0), [31, 39, 80, 30])
    # an outline thinner than twice the slack holds nothing on that axis
    np.testing.assert_array_equal(contain([40, 55, 80, 30], [30, 40, 3, 30], 2.0), [40, 42, 80, 30])
    assert contain(np.array([40.0, 55, 80, 30]), out).dtype == np.float64


def test_outline_contain_moves_a_drifted_box_and_its_frustum():
    """Stereo's outline is the lit part, a lower bound of the body: a 2D box beside it has drifted
    (a README stereo test sequence: EdgeTrack 9-18 px below a fully lit body's top). With
    outline_contain the frustum, the 3D box and the fusion start from the box moved onto it."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D
    from track3d.sensor_options import CONTAIN_SLACK_PX

    Low = _answering([30.0, 55.0, 80.0, 30.0])    # the body's size, 15 px low
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:110] = True                    # the outline: [30, 40, 80, 30]
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    res = {}
    for on in (False, True):
        t = Track3D(CAM, Low(), create_estimator("baseline"), silhouette=0.0, outline_share=0.0,
                    outline_contain=on, weight_3d=0.0)
        t.init(image, [30, 40, 80, 30], points=pts)
        res[on] = t.update(image, pts)
    np.testing.assert_allclose(res[False].box2d, [30.0, 55.0, 80.0, 30.0], atol=1e-9)
    np.testing.assert_allclose(res[True].box2d, [30.0, 40.0 + CONTAIN_SLACK_PX, 80.0, 30.0], atol=1e-3)
    np.testing.assert_array_equal(res[True].box2d_raw, res[False].box2d_raw)   # the tracker's own box reported
    # the frustum of the moved box holds more of the body: more points, the 3D box higher up
    assert res[True].num_points > res[False].num_points
    assert res[True].box3d[1] < res[False].box3d[1]
    # with the outline on, containment has nothing to add
    a, b = (Track3D(CAM, Low(), create_estimator("baseline"), silhouette=0.5, outline_contain=c, weight_3d=0.0)
            for c in (False, True))
    for t in (a, b):
        t.init(image, [30, 40, 80, 30], points=pts)
    np.testing.assert_array_equal(a.update(image, pts).box2d, b.update(image, pts).box2d)


def test_outline_contain_reads_a_callable_cloud_once():
    """Stereo from the pair (`StereoCloud.bind`) computes depth around the box it is given: the
    loop asks once, for the tracker's box, reads the outline in that cloud and moves the box as
    with a depth map (it used to ask only for the frustum, with no outline to read)."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    Low = _answering([30.0, 55.0, 80.0, 30.0])    # the body's size, 15 px low
    mask = np.zeros((120, 160), bool)
    mask[40:70, 30:110] = True                    # the outline: [30, 40, 80, 30]
    pts = _cloud(mask)
    asked = []

    def window(box):                              # the cloud of the box and 16 px around it
        asked.append(np.array(box, dtype=np.float64))
        x, y, w, h = box
        u = pts[:, 0] / pts[:, 2] * CAM.fx + CAM.cx
        v = pts[:, 1] / pts[:, 2] * CAM.fy + CAM.cy
        keep = (u > x - 16) & (u < x + w + 16) & (v > y - 16) & (v < y + h + 16)
        return pts[keep]
    image = np.zeros((120, 160, 3), np.uint8)
    out = {}
    for on in (False, True):
        t = Track3D(CAM, Low(), create_estimator("baseline"), silhouette=0.0, outline_share=0.0,
                    outline_contain=on, weight_3d=0.0, frustum_margin=0.0)
        t.init(image, [30, 40, 80, 30], points=pts)
        asked.clear()
        out[on] = t.update(image, window)
        assert len(asked) == 1
        np.testing.assert_array_equal(asked[0], [30.0, 55.0, 80.0, 30.0])
    np.testing.assert_allclose(out[False].box2d, [30.0, 55.0, 80.0, 30.0], atol=1e-9)
    np.testing.assert_allclose(out[True].box2d, [30.0, 42.0, 80.0, 30.0], atol=1e-3)   # y 55 -> 40 + 2 px slack
    assert out[True].num_points > out[False].num_points


def test_outline_contain_finds_a_body_the_tracker_left():
    """With containment on and no returns near the tracker's box (EdgeTrack left on the sky after
    the body went out of view and came back), the loop goes on from the body the whole view's
    depth shows; a blob of fewer than FIND_MIN_RETURNS returns is noise, not a body."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D
    from track3d.sensor_options import FIND_MIN_RETURNS

    OnSky = _answering([120.0, 5.0, 30.0, 20.0])   # far from any return
    mask = np.zeros((120, 160), bool)
    mask[60:90, 10:60] = True                      # the body: [10, 60, 50, 30]
    image = np.zeros((120, 160, 3), np.uint8)
    speck = np.zeros((120, 160), bool)
    speck[60:66, 10:16] = True                     # 36 returns: noise
    assert speck.sum() < FIND_MIN_RETURNS <= mask.sum()
    for cloud, want in ((_cloud(mask), [10.0, 60.0, 50.0, 30.0]), (_cloud(speck), [120.0, 5.0, 30.0, 20.0])):
        out = {}
        for on in (False, True):
            t = Track3D(CAM, OnSky(), create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                        outline_contain=on, weight_3d=0.0)
            t.init(image, [120, 5, 30, 20], points=_cloud(mask))
            out[on] = t.update(image, cloud)
        np.testing.assert_allclose(out[False].box2d, [120.0, 5.0, 30.0, 20.0], atol=1e-9)
        np.testing.assert_allclose(out[True].box2d, want, atol=1e-3)
    assert out[False].status == out[True].status == "no_points"   # the speck: held, as without it
    # from the pair (a cloud of the box's window) there is no whole view to search: nothing moves
    t = Track3D(CAM, OnSky(), create_estimator("baseline"), silhouette=0.0, outline_contain=True, weight_3d=0.0)
    t.init(image, [120, 5, 30, 20], points=_cloud(mask))
    full = _cloud(mask)
    np.testing.assert_allclose(t.update(image, lambda box: full).box2d, [120.0, 5.0, 30.0, 20.0], atol=1e-9)


def test_the_outline_contain_option_is_checked_recorded_and_by_sensor(tmp_path):
    from track3d.estimators import create_estimator
    from track3d.evaluation import TrackerSpec
    from track3d.tracker import Track3D
    from track3d.sensor_options import outline_contain_for, sensor_options
    from track3d.trackers2d import create_tracker

    assert outline_contain_for("stereo") is True and sensor_options("stereo")["outline_contain"] is True
    assert not (outline_contain_for("ideal") or outline_contain_for("ToF") or outline_contain_for(None))
    for bad in (1, "yes", None):
        with pytest.raises(ValueError, match="outline_contain must be True or False"):
            Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), outline_contain=bad)
    t = Track3D(CAM, create_tracker("kcf"), create_estimator("baseline"), outline_contain=True)
    assert t.describe()["options"]["outline_contain"] is True
    from test_loop import _plain_and
    a, b = _plain_and(tmp_path, {"name": "tof", "max_range_m": 30.0})
    assert TrackerSpec("oracle", "baseline").build(b).outline_contain is False
    assert TrackerSpec("oracle", "baseline", outline_contain=True).build(b).outline_contain is True


def test_find_body_hand_cases():
    from track3d.silhouette import find_body

    mask = np.zeros((120, 160), bool)
    mask[40:70, 100:130] = True           # a body at x 100..129
    mask[10:20, 10:20] = True             # a second one, smaller (10 x 10 of 30 x 30 cells' worth)
    pts = _cloud(mask)

    def find(near):
        return find_body(pts, np.asarray(near, float), CAM.M, (CAM.width, CAM.height), (0.1, 100.0))
    np.testing.assert_allclose(find([60, 40, 20, 20]), [100, 40, 30, 30], atol=1e-3)   # nearer the box
    np.testing.assert_allclose(find([0, 0, 20, 20]), [10, 10, 10, 10], atol=1e-3)
    assert find_body(np.zeros((0, 3), np.float32), np.array([0.0, 0, 10, 10]), CAM.M, (160, 120),
                     (0.1, 100.0)) is None


def test_the_loop_finds_a_body_the_2d_search_lost():
    """A body swinging faster than the 2D search left the tracker's box on empty space: the loop
    reported 'no_points' there until the body came back (SiamFC-edge, an engine test sequence:
    AO_3d 0.03 one pass); the depth shows where it went."""
    from track3d.estimators import create_estimator
    from track3d.tracker import NO_POINTS, TRACKING, Track3D

    Stuck = _answering([10.0, 40.0, 30.0, 30.0])  # on empty space
    mask = np.zeros((120, 160), bool)
    mask[40:70, 100:130] = True
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    for grow, status in ((0.0, NO_POINTS), (0.5, TRACKING)):
        t = Track3D(CAM, Stuck(), create_estimator("baseline"), silhouette=grow)
        t.init(image, [100, 40, 30, 30], points=pts)
        r = t.update(image, pts)
        assert r.status == status
    assert iou_2d(r.box2d[None], np.array([[100.0, 40, 30, 30]]))[0] > 0.98


def test_a_lost_tracker_with_the_body_in_depth_gets_the_outlines_3d_box():
    """EdgeTrack calls the body lost when a sliver is left at the image border; the depth held
    the frame ('no_points') with the last 3D box. The 3D box now comes from the returns' outline
    at the last box, and so does the reported 2D box (the sliver in view); the loop's own box and
    the tracker stay as they were."""
    from track3d.estimators import create_estimator
    from track3d.tracker import NO_POINTS, Track3D

    class Losing:
        lost = False

        def init(self, image, box):
            pass

        def update(self, image):
            self.lost = True
            return False, np.array([60.0, 40.0, 30.0, 30.0])

    mask = np.zeros((120, 160), bool)
    mask[40:70, 60:90] = True
    whole = _cloud(mask)
    mask[:, 70:] = False                   # next frame: only a 10-pixel sliver still in view
    sliver = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    boxes = {}
    for grow in (0.0, 0.5):
        t = Track3D(CAM, Losing(), create_estimator("baseline"), silhouette=grow, evidence_points=16)
        t.init(image, [60, 40, 30, 30], points=whole)
        before = t.box3d.copy()
        r = t.update(image, sliver)
        assert r.status == NO_POINTS
        np.testing.assert_allclose(r.box2d, [60, 40, 30, 30] if grow == 0.0 else [60, 40, 10, 30], atol=1e-3)
        np.testing.assert_array_equal(t.box2d, [60, 40, 30, 30])
        boxes[grow] = r.box3d
    np.testing.assert_array_equal(boxes[0.0], before)                 # held
    assert boxes[0.5][0] < before[0] and not np.array_equal(boxes[0.5], before)   # the sliver's side


def test_past_border_hand_cases():
    from track3d.silhouette import past_border

    W, H = CAM.width, CAM.height
    # the outline at the left and bottom borders, the tracker's box past them: its sides there
    np.testing.assert_allclose(past_border(np.array([0.0, 50, 40, 70]), np.array([-20.0, 60, 50, 80]), (W, H)),
                               [-20, 50, 40 + 20, 90])
    # a side off the border keeps the outline's, even when the tracker's reaches farther
    np.testing.assert_allclose(past_border(np.array([10.0, 10, 30, 30]), np.array([0.0, 0, 60, 60]), (W, H)),
                               [10, 10, 30, 30])
    # a tracker's box inside the outline at the border does not shrink it
    np.testing.assert_allclose(past_border(np.array([0.0, 0, 30, 30]), np.array([5.0, 5, 10, 10]), (W, H)),
                               [0, 0, 30, 30])


def test_a_body_coming_into_view_keeps_the_trackers_box_past_the_border():
    """The outline stops at the image border; the loop took it as the 2D box and corrected the
    tracker onto the visible part of a body coming into view (the ./run.sh demo lost it: one
    restart)."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    Past = _answering([-30.0, 40.0, 60.0, 30.0])   # the body's left half beyond the border
    mask = np.zeros((120, 160), bool)
    mask[40:70, 0:30] = True
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    t = Track3D(CAM, Past(), create_estimator("baseline"), silhouette=0.5, weight_3d=0.0)
    t.init(image, [-30, 40, 60, 30], points=pts)
    r = t.update(image, pts)
    # the loop (and the tracker it corrects) keeps the box past the border
    assert t.box2d[0] < -25 and abs(t.box2d[0] + t.box2d[2] - 30) < 1.5
    # the reported box is clipped to the image, as the labels are; the tracker's own box is not
    np.testing.assert_allclose(r.box2d, [0, 40, t.box2d[0] + t.box2d[2], 30])
    np.testing.assert_array_equal(r.box2d_raw, [-30, 40, 60, 30])


def test_a_lost_tracker_is_taken_to_the_body_the_depth_shows_whole():
    """EdgeTrack lost a body that swung back into view (accuracy set test 0005: 15 frames lost
    while the depth showed it whole). With the outline on, a frame the tracker calls lost with
    no returns at its last box goes on from the body in the whole view's depth, and the tracker
    is corrected onto it; no depth or the outline off keep 'lost' (a body at the image border:
    the next test)."""
    from track3d.estimators import create_estimator
    from track3d.tracker import LOST, TRACKING, Track3D

    Losing = _losing([10.0, 10.0, 20.0, 20.0])
    start = np.zeros((120, 160), bool)
    start[10:30, 10:30] = True
    elsewhere = np.zeros((120, 160), bool)
    elsewhere[60:90, 100:130] = True        # the body, whole, far from the last box
    at_border = np.zeros((120, 160), bool)
    at_border[60:90, 140:160] = True        # the body cut by the right border
    image = np.zeros((120, 160, 3), np.uint8)

    def run(mask, silhouette=0.5, empty=False):
        tr = Losing()
        t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=silhouette, weight_3d=0.0)
        t.init(image, [10, 10, 20, 20], points=_cloud(start))
        pts = np.zeros((0, 3), np.float32) if empty else _cloud(mask)
        return t.update(image, pts), tr

    r, tr = run(elsewhere)
    assert r.status == TRACKING
    np.testing.assert_allclose(r.box2d, [99.5, 59.5, 31, 31], atol=1.0)   # the returns' outline
    np.testing.assert_allclose(tr.corrected, r.box2d)
    np.testing.assert_array_equal(r.box2d_raw, [10, 10, 20, 20])          # the tracker's own answer
    assert 10.0 < r.box3d[2] < 10.5
    for kw in ({"mask": elsewhere, "silhouette": 0.0}, {"mask": elsewhere, "empty": True}):
        r, tr = run(**kw)
        assert r.status == LOST and tr.corrected is None
        np.testing.assert_array_equal(r.box2d, [10, 10, 20, 20])


def test_a_lost_tracker_with_the_body_at_the_border_is_held_on_it():
    """A body that left the view at the border and came back there (ideal long watch, test 0005):
    EdgeTrack, drifted onto the sky, called it lost with no returns at its last box, and the loop
    kept the last 3D box for 7 frames ('lost') while the depth showed the body at the border.
    The frame is held on that body: its 3D box measured from the outline, the outline reported,
    status 'no_points' (not a bad frame); the tracker is not corrected onto a body the border cuts
    (it did not re-acquire the body when it came back whole: held-out 0011), so the next frame
    with the body whole goes on from it as before."""
    from track3d.estimators import create_estimator
    from track3d.tracker import LOST, NO_POINTS, TRACKING, Track3D

    start = np.zeros((120, 160), bool)
    start[10:30, 10:30] = True
    at_border = np.zeros((120, 160), bool)
    at_border[60:90, 140:160] = True        # the body cut by the right border
    whole = np.zeros((120, 160), bool)
    whole[60:90, 110:140] = True
    image = np.zeros((120, 160, 3), np.uint8)
    tr = _losing([10.0, 10.0, 20.0, 20.0])()
    t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=0.5, weight_3d=0.0, lost_after=1)
    t.init(image, [10, 10, 20, 20], points=_cloud(start))
    first = t.box3d.copy()
    held = [t.update(image, _cloud(at_border)) for _ in range(3)]
    assert [r.status for r in held] == [NO_POINTS] * 3 and t.bad_frames == 0
    np.testing.assert_allclose(held[0].box2d, [139.5, 59.5, 20.5, 31], atol=1.0)   # the outline, clipped
    assert tr.corrected is None
    np.testing.assert_allclose(t.box2d, [10, 10, 20, 20])                          # the loop's own box
    assert held[0].box3d[0] > first[0] + 1.0                                      # measured at the border
    back = t.update(image, _cloud(whole))
    assert back.status == TRACKING
    np.testing.assert_allclose(tr.corrected, back.box2d)
    # no body in the depth: lost, the last 3D box kept
    t = Track3D(CAM, _losing([10.0, 10.0, 20.0, 20.0])(), create_estimator("baseline"), silhouette=0.5)
    t.init(image, [10, 10, 20, 20], points=_cloud(start))
    r = t.update(image, np.zeros((0, 3), np.float32))
    assert r.status == LOST
    np.testing.assert_array_equal(r.box3d, t.box3d)


def test_a_lost_tracker_with_returns_at_its_last_box_is_not_moved():
    """The body-in-view rule is for a body elsewhere: returns at the last box (fewer than the
    depth-held rule's evidence) leave the frame 'lost' and the tracker where it was (it failed
    test_state's 47-return case when it ran on any lost frame)."""
    from track3d.estimators import create_estimator
    from track3d.tracker import LOST, Track3D

    Losing = _losing([10.0, 10.0, 20.0, 20.0])
    mask = np.zeros((120, 160), bool)
    mask[10:30, 10:30] = True
    pts = _cloud(mask)
    image = np.zeros((120, 160, 3), np.uint8)
    for evidence in (0, 10 ** 6):    # off, or more returns than the body has
        t = Track3D(CAM, Losing(), create_estimator("baseline"), silhouette=0.5, evidence_points=evidence)
        t.init(image, [10, 10, 20, 20], points=pts)
        r = t.update(image, pts)
        assert r.status == LOST and t.tracker2d.corrected is None


def test_a_sparse_cloud_moves_no_2d_box(tmp_path):
    """A body mostly in shadow gives stereo depth only on a lit sliver (a README stereo long watch:
    1,160 returns in a 557 x 383 px box). Its outline and its 3D box are a sliver's: shared into
    the 2D box and fused, they shrank the box to the sliver, the 2D tracker was corrected onto it
    and lost the body. With fewer returns than `fusion_cover` of the box's pixels the tracker's
    box stands and is what the tracker is corrected with; a cloud over the whole body is fused as
    before. The option is checked, recorded, and by sensor."""
    from track3d.estimators import create_estimator
    from track3d.evaluation import TrackerSpec
    from track3d.tracker import Track3D
    from track3d.sensor_options import fusion_cover_for, sensor_options

    box = [20.0, 20.0, 120.0, 80.0]                # the body's box: 9,600 px
    sliver = np.zeros((120, 160), bool)
    sliver[90:100, 100:140] = True                 # 400 px lit (4%), in the box's low right corner
    whole = np.zeros((120, 160), bool)
    whole[20:100, 20:140] = True
    image = np.zeros((120, 160, 3), np.uint8)

    def run(mask, cover):
        Tracker = _losing(box)
        Tracker.update = lambda self, image: (True, np.array(box))   # tracking, never lost
        tr = Tracker()
        t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                    outline_contain=True, weight_3d=0.15, fusion_cover=cover)
        pts = _cloud(mask)
        t.init(image, box, points=pts)
        r = t.update(image, pts)
        return r, tr.corrected

    shrunk, onto = run(sliver, 0.0)
    kept, onto_kept = run(sliver, 0.05)
    assert iou_2d(shrunk.box2d, box) < 0.8 and np.allclose(onto, shrunk.box2d)   # the failure
    np.testing.assert_allclose(kept.box2d, box, atol=1e-9)
    np.testing.assert_allclose(onto_kept, box, atol=1e-9)
    np.testing.assert_array_equal(kept.box3d, shrunk.box3d)          # the 3D box is the cloud's either way
    # a whole body's cloud (100% of the box) is fused alike with the rule on and off
    a, _ = run(whole, 0.0)
    b, _ = run(whole, 0.05)
    np.testing.assert_array_equal(a.box2d, b.box2d)

    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="fusion_cover must be in"):
            Track3D(CAM, _answering(box)(), create_estimator("baseline"), fusion_cover=bad)
    t = Track3D(CAM, _answering(box)(), create_estimator("baseline"), fusion_cover=0.05)
    assert t.describe()["options"]["fusion_cover"] == 0.05
    assert "fusion_cover" not in Track3D(CAM, _answering(box)(), create_estimator("baseline")).describe()["options"]
    assert fusion_cover_for("ideal") == fusion_cover_for(None) == 0.0
    assert sensor_options("stereo")["fusion_cover"] == fusion_cover_for("stereo")
    from test_loop import _plain_and
    _, tof = _plain_and(tmp_path, {"name": "tof", "max_range_m": 30.0})
    assert TrackerSpec("oracle", "baseline").build(tof).fusion_cover == 0.0
    assert TrackerSpec("oracle", "baseline", fusion_cover=0.2).build(tof).fusion_cover == 0.2


def test_a_lost_tracker_on_a_lit_body_is_held_and_measured_not_lost():
    """Stereo (the outline is the lit part, `outline_contain`): EdgeTrack drifted off a half-lit
    body and called it lost while 17,000 returns showed the body in its last box (a README stereo
    long watch: 65 frames "lost"). Held frames whose 3D box is measured from the frustum of the
    last box moved onto the lit outline are not bad frames: the status stays "no_points" past
    `lost_after`, the 3D box follows the returns, the 2D box and the tracker stay where they
    were; with no returns there the frames count again. Without containment (the old rule for a
    cloud whose outline is not read) the same frames turn "lost" after `lost_after`."""
    from track3d.estimators import create_estimator
    from track3d.tracker import LOST, NO_POINTS, Track3D

    box = [30.0, 30.0, 80.0, 60.0]
    image = np.zeros((120, 160, 3), np.uint8)

    def lit(dx):   # the lit half of the body: pixels x 30+dx..69+dx, y 30..89
        m = np.zeros((120, 160), bool)
        m[30:90, 30 + dx:70 + dx] = True
        return _cloud(m)

    def run(contain):
        tr = _losing(box)()
        tr.update = lambda image: (True, np.array(box))
        t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                    outline_contain=contain, weight_3d=0.15, lost_after=3)
        t.init(image, box, points=lit(0))
        t.update(image, lit(0))
        tr.corrected = None
        tr.update = lambda image: (tr.__setattr__("lost", True), (False, np.array(box)))[1]
        return t, tr, [t.update(image, lit(k)) for k in range(1, 7)]

    t, tr, held = run(True)
    assert [r.status for r in held] == [NO_POINTS] * 6 and held[-1].held_frames == 6
    assert held[-1].box3d[0] > held[0].box3d[0] + 0.04          # measured: it follows the lit part right
    assert all(np.array_equal(r.box2d, held[0].box2d) for r in held) and tr.corrected is None
    empty = np.zeros((0, 3), np.float32)
    assert [t.update(image, empty).status for _ in range(3)][-1] == LOST
    _, _, old = run(False)
    assert [r.status for r in old] == [NO_POINTS, NO_POINTS, LOST, LOST, LOST, LOST]


def test_a_lost_tracker_on_a_lit_body_in_view_goes_on_from_it_with_resume_outline():
    """Stereo (the outline is the lit part, `outline_contain`) with `resume_outline`: EdgeTrack
    called a half-lit body lost while the depth showed it in its last box, and the held 2D box
    stayed there for 74 frames (README stereo long watch, test 0005: IoU_2d 0.53-0.81 while the
    body moved on). The frame goes on from the last box moved onto the lit outline: 'tracking',
    the tracker corrected onto that box, which follows the lit part. A lit outline cut by the
    image border on one side only (a body leaving the view) stays held."""
    from track3d.estimators import create_estimator
    from track3d.tracker import NO_POINTS, TRACKING, Track3D

    box = [30.0, 30.0, 80.0, 60.0]
    image = np.zeros((120, 160, 3), np.uint8)

    def lit(dx, x0=30, w=40):   # the lit part of the body: pixels x x0+dx..x0+dx+w-1, y 30..89
        m = np.zeros((120, 160), bool)
        m[30:90, max(x0 + dx, 0):x0 + w + dx] = True
        return _cloud(m)

    def run(resume, x0=30, w=40):
        tr = _losing(box)()
        tr.update = lambda image: (True, np.array(box))
        t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                    outline_contain=True, weight_3d=0.15, resume_outline=resume)
        t.init(image, box, points=lit(0))
        t.update(image, lit(0))
        tr.corrected = None
        tr.update = lambda image: (tr.__setattr__("lost", True), (False, np.array(box)))[1]
        return t, tr, [t.update(image, lit(k * 4, x0, w)) for k in range(1, 4)]

    t, tr, on = run(True)
    assert [r.status for r in on] == [TRACKING] * 3 and tr.corrected is not None
    assert on[-1].box2d[0] > on[0].box2d[0] + 4.0          # it follows the lit part right
    np.testing.assert_allclose(t.box2d, tr.corrected)
    _, tr_off, off = run(False)
    assert [r.status for r in off] == [NO_POINTS] * 3 and tr_off.corrected is None
    assert all(np.array_equal(r.box2d, off[0].box2d) for r in off)
    _, tr_cut, cut = run(True, x0=-20, w=80)               # cut by the left border only
    assert [r.status for r in cut] == [NO_POINTS] * 3 and tr_cut.corrected is None
    assert [r.status for r in run(True, x0=10, w=80)[2]] == [TRACKING] * 3   # the same body, whole


def test_a_held_frame_reports_the_sliver_in_view_and_keeps_its_own_box():
    """A 2D tracker that calls a body leaving the view lost, while the depth holds a sliver of it
    at the last box: the frame is held and its 3D box measured from the sliver's outline, and it
    reported the last box as its 2D box (IoU_2d 0.13 against the label, the sliver's box; the
    README's ideal test 0003, frames 5 and 9). It reports the sliver; the loop's own box and the
    tracker stay as they were, so the body coming back whole is found where it left."""
    from track3d.estimators import create_estimator
    from track3d.tracker import NO_POINTS, Track3D

    Losing = _losing([20.0, 0.0, 40.0, 40.0])
    whole = np.zeros((120, 160), bool)
    whole[0:40, 20:60] = True
    sliver = np.zeros((120, 160), bool)
    sliver[0:6, 20:60] = True
    image = np.zeros((120, 160, 3), np.uint8)
    t = Track3D(CAM, Losing(), create_estimator("baseline"), silhouette=0.5, weight_3d=0.0)
    t.init(image, [20, 0, 40, 40], points=_cloud(whole))
    r = t.update(image, _cloud(sliver))
    assert r.status == NO_POINTS
    np.testing.assert_allclose(r.box2d, [20, 0, 40, 6], atol=1e-3)
    np.testing.assert_allclose(t.box2d, [20, 0, 40, 40])
    assert t.tracker2d.corrected is None
    assert r.box3d[4] < 1.0 < 40 / CAM.fy * 10.0           # the sliver's height, measured (m)


def test_a_lone_return_is_no_outline():
    """A false alarm alone in the tracker's box (a body past the ToF range) had become a 1 x 1 px
    outline, reported as the 2D box and carried on; an outline needs MIN_CELLS occupied cells."""
    from track3d.silhouette import MIN_CELLS

    mask = np.zeros((CAM.height, CAM.width), bool)
    mask[60, 80] = True
    assert MIN_CELLS > 1 and _box(_cloud(mask), [70, 50, 20, 20]) is None
    mask[55:65, 75:85] = True
    np.testing.assert_allclose(_box(_cloud(mask), [70, 50, 20, 20]), [75, 55, 10, 10])


def test_the_outline_does_not_reach_a_lone_return_the_raster_skipped():
    """A cloud past RASTER_POINTS is rasterised every k-th return: a false alarm the stride left out
    lay in no component, yet the outline of 'every component' took every return's extent and
    reached out to it (100 px past a ToF body)."""
    from track3d.silhouette import RASTER_POINTS

    cam = Camera.from_fov(640, 480, 45.0)
    mask = np.zeros((480, 640), bool)
    mask[100:300, 200:400] = True                       # 40,000 returns: a stride of 7
    assert mask.sum() > RASTER_POINTS
    pts = cam.backproject_depth(np.where(mask, 10.0, 0.0).astype(np.float32))
    stray = cam.backproject_depth(np.where(np.arange(640)[None, :] + 0 * np.arange(480)[:, None] == 150,
                                           12.0, 0.0).astype(np.float32))[:1]   # one return at u = 150, v = 0.5
    for cloud in (pts, np.concatenate([pts, stray])):   # the stray last: the stride skips it
        out = silhouette_box(cloud, np.array([200.0, 100, 200, 200]), cam.M, (640, 480), (0.1, 100.0), 0.5)[0]
        np.testing.assert_allclose(out, [200, 100, 200, 200])


def test_find_body_without_lone_out_is_the_search_before_the_false_alarm_rules():
    """Track3D(drop_stray=False) promises the loop before the rules: the whole-view search passed
    no lone_out and took a stride-skipped lone return into the body's box."""
    from track3d.silhouette import find_body

    cam = Camera.from_fov(640, 480, 45.0)
    mask = np.zeros((480, 640), bool)
    mask[200:300, 250:380] = True                       # 13,000 returns: a stride of 3
    pts = cam.backproject_depth(np.where(mask, 10.0, 0.0).astype(np.float32))
    lone = cam.backproject_depth(np.where((np.arange(640)[None, :] == 600) & (np.arange(480)[:, None] == 100),
                                          10.0, 0.0).astype(np.float32))
    cloud = np.concatenate([pts[:1], lone, pts[1:]])   # at index 1: the stride skips it
    near = np.array([250.0, 200, 130, 100])
    np.testing.assert_allclose(find_body(cloud, near, cam.M, (640, 480), (0.1, 100.0)), [250, 200, 130, 100])
    old = find_body(cloud, near, cam.M, (640, 480), (0.1, 100.0), lone_out=False)
    assert old[0] + old[2] > 600                        # as before the rules: out to the lone return
