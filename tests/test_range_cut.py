"""A body reaching past the depth sensor's range is boxed from the image (track3d.range_cut)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from track3d.boxes import box3d_from_points, iou_3d
from track3d.camera import Camera
from track3d.range_cut import DEPTH_RATIO, MIN_COVERAGE, box_from_view, is_range_cut, lateral_coverage
from track3d.synthetic import CAM, render_sphere
from track3d.tracker import TRACKING, Track3D
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
    the 2D fusion keeps the estimator's box (see Track3D._range_cut)."""
    img, pts, b2, b3 = _cut_sphere(30.0)
    assert 0 < len(pts) and np.linalg.norm(pts, axis=1).max() <= 30.0
    gt2d = np.array([b2, b2])
    out = {}
    for rng in (None, 30.0):
        t = Track3D(CAM, OracleTracker(gt2d), _CapBox(), depth_range_m=rng)
        t.init(img, b2)
        r = t.update(img, pts)
        assert r.status == TRACKING
        out[rng] = r
        assert t.describe()["options"]["depth_range_m"] == rng
    cap = box3d_from_points(pts[(np.abs(pts[:, 0]) < 10)])
    np.testing.assert_allclose(out[None].box3d, cap)
    lo = pts.min(axis=0)
    np.testing.assert_allclose(out[30.0].box3d, box_from_view(b2, CAM, float(lo[2])))
    assert iou_3d(out[30.0].box3d, b3) > 0.6 > 0.3 > iou_3d(out[None].box3d, b3)
    np.testing.assert_allclose(out[30.0].box2d, out[None].box2d)      # fusion unchanged
    # a body in range is the estimator's, range or not
    img, pts, b2, b3 = _cut_sphere(45.0)
    t = Track3D(CAM, OracleTracker(np.array([b2, b2])), _CapBox(), depth_range_m=45.0)
    t.init(img, b2)
    np.testing.assert_allclose(t.update(img, pts).box3d, box3d_from_points(pts))


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
    rec = read_run_record(res, "test", "oracle+baseline")
    assert rec["track3d"]["options"]["depth_range_m"] == 30.0 and rec["track3d"]["options"]["measured_faces"] is True
    assert read_run_record(res, "test", "norange")["track3d"]["options"]["depth_range_m"] is None
    assert read_run_record(res, "test", "nofront")["track3d"]["options"]["measured_faces"] is False
