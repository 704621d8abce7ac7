"""The body's dark side from the sun's direction (track3d.dark_side) and the loop's use of it."""
import json

import numpy as np
import pytest

from track3d.camera import Camera
from track3d.dark_side import check_sun, dark_share, dark_side_box, phase_deg, reach_dark_side

CAM = Camera.from_fov(200, 200, 60.0)   # cx = cy = 100: a box centred there looks along z


def test_dark_share_hand_cases():
    """A box at the image centre: the phase angle is the angle between the sun and the camera
    (-z). Sun along +x: 90 degrees, a sphere's dark part equals its lit part (ratio 1); sun
    halfway between +x and the camera: 45 degrees, (1 - cos) / (1 + cos) = 0.1716; the share is
    k times that, capped; the sun on the line of sight gives no side."""
    box = np.array([75.0, 75.0, 50.0, 50.0])
    share, u = dark_share(box, np.array([1.0, 0.0, 0.0]), CAM, 0.5)
    assert share == pytest.approx(0.5) and np.allclose(u, [1.0, 0.0])
    share, u = dark_share(box, np.array([1.0, 0.0, -1.0]) / np.sqrt(2.0), CAM, 1.0)
    assert share == pytest.approx((1 - np.sqrt(0.5)) / (1 + np.sqrt(0.5))) and np.allclose(u, [1.0, 0.0])
    share, _ = dark_share(box, np.array([0.0, 1.0, 0.2]), CAM, 1.0, cap=0.7)   # past 90 degrees: capped
    assert share == pytest.approx(0.7)
    assert dark_share(box, np.array([0.0, 0.0, -1.0]), CAM, 1.0) is None
    assert dark_share(box, np.array([0.0, 0.0, 1.0]), CAM, 1.0) is None


def test_the_dark_side_lies_away_from_the_sun():
    """Sun along +x at 90 degrees of phase, k = 0.5: the lit outline [80, 60, 40, 80] grows by
    0.5 x 40 = 20 px on its left (low x) side; sun along +y (below): by 0.5 x 80 = 40 px on top;
    sun along -x: on the right. The sides toward the sun stay."""
    lit = np.array([80.0, 60.0, 40.0, 80.0])
    np.testing.assert_allclose(dark_side_box(lit, np.array([1.0, 0, 0]), CAM, 0.5), [60, 60, 60, 80])
    np.testing.assert_allclose(dark_side_box(lit, np.array([0, 1.0, 0]), CAM, 0.5), [80, 20, 40, 120])
    np.testing.assert_allclose(dark_side_box(lit, np.array([-1.0, 0, 0]), CAM, 0.5), [80, 60, 60, 80])
    # diagonal sun: each axis by its share of the image direction
    d = dark_side_box(lit, np.array([1.0, 1.0, 0]) / np.sqrt(2.0), CAM, 0.5)
    np.testing.assert_allclose(d, [80 - 20 * np.sqrt(0.5), 60 - 40 * np.sqrt(0.5),
                                   40 + 20 * np.sqrt(0.5), 80 + 40 * np.sqrt(0.5)])
    np.testing.assert_array_equal(dark_side_box(lit, np.array([1.0, 0, 0]), CAM, 0.0), lit)   # off
    assert dark_side_box(lit, np.array([1.0, 0, 0]), CAM, 0.5) is not lit


def test_reach_dark_side_only_pushes_the_sides_away_from_the_sun():
    sun = np.array([1.0, 0.0, 0.0])     # dark side: low x
    dark = np.array([60.0, 60.0, 60.0, 80.0])
    np.testing.assert_allclose(reach_dark_side([80, 50, 50, 100], dark, sun, CAM), [60, 50, 70, 100])
    # a box already past the dark outline, or narrower on the lit side, is not pulled in
    np.testing.assert_allclose(reach_dark_side([50, 50, 50, 100], dark, sun, CAM), [50, 50, 50, 100])
    np.testing.assert_allclose(reach_dark_side([90, 90, 20, 20], dark, sun, CAM), [60, 90, 50, 20])
    up = np.array([0.0, -1.0, 0.0])      # sun above: dark side at high y
    np.testing.assert_allclose(reach_dark_side([60, 60, 60, 50], dark, up, CAM), [60, 60, 60, 80])


def test_phase_deg_hand_cases():
    """At the image centre the phase is the angle between the sun and the camera (-z): sun
    behind the camera 0, across the line of sight 90, behind the body 180, halfway 45 / 135. Off
    the centre the box's own ray counts: a box at the right edge of a 60-degree view looks 30
    degrees right, so seen from the body the observer lies 120 degrees from a sun along +x (lit
    more from behind than a body on the axis) and 60 degrees from one along -x."""
    box = np.array([75.0, 75.0, 50.0, 50.0])
    for sun, want in (([0, 0, -1.0], 0.0), ([1.0, 0, 0], 90.0), ([0, 0, 1.0], 180.0),
                      ([1.0, 0, -1.0], 45.0), ([0, 1.0, 1.0], 135.0)):
        assert phase_deg(box, check_sun(sun), CAM) == pytest.approx(want)
    right = np.array([199.0, 95.0, 2.0, 10.0])   # centre x = 200: tan 30 deg off the axis
    assert phase_deg(right, check_sun([1.0, 0, 0]), CAM) == pytest.approx(120.0, abs=1e-6)
    assert phase_deg(right, check_sun([-1.0, 0, 0]), CAM) == pytest.approx(60.0, abs=1e-6)


def test_past_the_share_phase_the_lit_outline_moves_no_box():
    """The tracker boxes the whole sphere; the depth holds its lit half (sun along +x: 90 degrees
    at the box). With outline_share 0.3 and no fusion weight the fusion starts from 0.3 x the lit
    outline + 0.7 x the tracker's box; with the sun known and outline_share_phase below 90 it
    starts from the tracker's box; at or above 90, or with the sun unknown, the share stays. The
    option is recorded only when on."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    img, pts, true2d, lit = _half_lit_sphere()
    shared = 0.3 * lit + 0.7 * true2d
    for limit, sun, want in ((180.0, [1.0, 0, 0], shared), (60.0, [1.0, 0, 0], true2d),
                             (120.0, [1.0, 0, 0], shared), (60.0, None, shared)):
        t = Track3D(CAM, _Lit(true2d), create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                    outline_share_phase=limit, weight_3d=0.0)
        t.set_sun(sun)
        t.init(img, true2d)
        r = t.update(img, pts)
        np.testing.assert_allclose(r.box2d, want, atol=1e-6, err_msg=f"{limit} {sun}")
        opts = t.describe()["options"]
        assert opts.get("outline_share_phase") == (None if limit == 180.0 else limit)
    for bad in (-1.0, 181.0, float("nan")):
        with pytest.raises(ValueError, match="outline_share_phase"):
            Track3D(CAM, _Lit(true2d), create_estimator("baseline"), outline_share_phase=bad)


def test_check_sun():
    np.testing.assert_allclose(check_sun([0, 3.0, 4.0]), [0, 0.6, 0.8])
    assert check_sun(None) is None
    for bad in ([0, 0, 0], [1, 2], [np.nan, 0, 1], "up"):
        with pytest.raises(ValueError, match="sun direction"):
            check_sun(bad)


class _Lit:
    """A 2D tracker that boxes the lit half of the body (what a camera sees at 90 degrees of phase)."""

    def __init__(self, box):
        self.box = np.asarray(box, np.float64)

    def init(self, image, box):
        pass

    def update(self, image):
        return True, self.box.copy()

    def correct(self, box):
        self.corrected = np.asarray(box, np.float64).copy()

    def get_state(self):
        return {"box": self.box.tolist()}

    def set_state(self, st):
        self.box = np.asarray(st["box"], np.float64)


def _half_lit_sphere():
    """A sphere lit from +x: depth only on its lit (right) half, as stereo matching gives; the
    true 2D box and the lit half's."""
    from track3d.synthetic import render_sphere

    img, depth, b2, _ = render_sphere(CAM, (0.0, 0.0, 10.0), 2.0)
    cols = np.arange(CAM.width)[None, :]
    lit_depth = np.where(cols >= CAM.cx, depth, 0.0).astype(np.float32)
    ys, xs = np.nonzero(lit_depth > 0)
    lit = np.array([xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1], np.float64)
    return img, CAM.backproject_depth(lit_depth), b2, lit


def test_the_loop_reaches_into_the_dark_side_with_the_sun_known():
    """Sun along +x (90 degrees of phase): the tracker boxes the lit half, the depth holds only
    that half. With the sun and dark_side = 1 (a sphere's own ratio) the reported box reaches
    the sphere's left limb; without the sun, or at 0, it stays on the lit half. The last push
    comes after the tracker's correction; the sun is part of the state."""
    from track3d.estimators import create_estimator
    from track3d.tracker import Track3D

    img, pts, true2d, lit = _half_lit_sphere()
    reported = {}
    for k, sun in ((0.0, [1.0, 0, 0]), (1.0, None), (1.0, [1.0, 0, 0])):
        t = Track3D(CAM, _Lit(lit), create_estimator("baseline"), silhouette=0.0, outline_contain=True,
                    dark_side=k)
        t.set_sun(sun)
        t.init(img, lit)
        r = t.update(img, pts)
        reported[(k, sun is None)] = r.box2d
        if k > 0 and sun is not None:
            assert t.tracker2d.corrected[0] > r.box2d[0] + 1.0   # the last push is not fed back
            assert t.describe()["options"]["dark_side"] == 1.0
            st = json.loads(json.dumps(t.get_state()))
            t2 = Track3D(CAM, _Lit(lit), create_estimator("baseline"), silhouette=0.0, outline_contain=True,
                         dark_side=k)
            t2.set_state(st)
            np.testing.assert_allclose(t2.sun, [1.0, 0, 0])
    left = {key: b[0] for key, b in reported.items()}
    assert abs(left[(1.0, False)] - true2d[0]) < 0.1 * true2d[2], (left, true2d)
    for key in ((0.0, False), (1.0, True)):
        assert left[key] > true2d[0] + 0.35 * true2d[2], (key, left, true2d)
    for bad in (-0.1, 2.5, float("nan")):
        with pytest.raises(ValueError, match="dark_side"):
            Track3D(CAM, _Lit(lit), create_estimator("baseline"), dark_side=bad)


def test_the_sequence_s_sun_reaches_the_loop(tmp_path):
    """Sequence.sun_direction reads meta.json's sun (unit vector, None when absent or bad);
    TrackerSpec hands it to Track3D unless told not to; dark_side is off for every sensor unless
    asked for."""
    from track3d.dataset import Dataset
    from track3d.evaluation import TrackerSpec
    from track3d.synthetic import make_synthetic_dataset
    from track3d.sensor_options import dark_side_for, sensor_options

    root = make_synthetic_dataset(tmp_path / "d", {"a": 3, "b": 3})
    for name, sun in (("a", {"direction": [0.0, 2.0, 0.0]}), ("b", {"direction": [0.0, "x", 1.0]})):
        meta = root / "test" / name / "meta.json"
        m = json.loads(meta.read_text())
        m["sun"] = sun
        m["depth_sensor"] = {"name": "stereo"}
        meta.write_text(json.dumps(m))
    a, b = Dataset(root).sequences("test")
    np.testing.assert_allclose(a.sun_direction, [0, 1, 0])
    assert b.sun_direction is None
    t = TrackerSpec("oracle", "baseline").build(a)
    np.testing.assert_allclose(t.sun, [0, 1, 0])
    assert t.dark_side == dark_side_for("stereo") == sensor_options("stereo")["dark_side"] == 0.0   # off
    assert TrackerSpec("oracle", "baseline", sun=False).build(a).sun is None
    assert TrackerSpec("oracle", "baseline", dark_side=0.1).build(a).dark_side == 0.1
    assert dark_side_for("ideal") == dark_side_for("tof") == dark_side_for(None) == 0.0
