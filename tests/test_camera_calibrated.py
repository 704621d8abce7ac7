"""A calibrated camera (fx != fy, principal point off centre, distortion): K drives the frustum,
fusion, projection and back-projection; from_dict accepts such a K."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.camera import Camera
from track3d.frustum import extract_frustum, extract_frustum_numpy
from track3d.fusion import fuse

CAM = Camera.from_intrinsics(200, 100, fx=100.0, fy=50.0, cx=60.0, cy=30.0)


def test_K_and_M_are_the_given_intrinsics():
    assert np.array_equal(CAM.K, [[100, 0, 60], [0, 50, 30], [0, 0, 1]])
    assert np.array_equal(CAM.M, [[100, 0, 60, 0], [0, 50, 30, 0], [0, 0, 1, 0]])
    assert CAM.calibrated and not Camera.from_fov(200, 100, 60.0).calibrated


def test_projection_hand_computed():
    # u = 100 * 1 / 10 + 60 = 70, v = 50 * 2 / 10 + 30 = 40
    assert np.allclose(CAM.project([[1.0, 2.0, 10.0]]), [[70.0, 40.0]])


def test_frustum_uses_the_off_centre_principal_point():
    pts = np.array([[1.0, 2.0, 10.0], [5.0, 2.0, 10.0]], np.float32)   # -> (70, 40) and (110, 40)
    for extract in (extract_frustum, extract_frustum_numpy):
        got = extract(pts, np.array([69.0, 39.0, 2.0, 2.0]), CAM.M)
        assert np.allclose(got, pts[:1])
        # where the first point would land with a centred principal point (cx = 100, cy = 50): nothing
        assert len(extract(pts, np.array([109.0, 59.0, 2.0, 2.0]), CAM.M)) == 0


def test_fusion_hand_computed():
    # box [1, 2, 10, 2, 4, 6]: x 0..2 -> u 60..80, y 0..4 -> v 30..50 -> A_proj [60, 30, 20, 20]
    assert np.allclose(CAM.project_box3d_section(np.array([1.0, 2, 10, 2, 4, 6])), [60, 30, 20, 20])
    fused = fuse(np.array([70.0, 40, 10, 10]), np.array([1.0, 2, 10, 2, 4, 6]), CAM, 0.3)
    assert np.allclose(fused, [67.0, 37.0, 13.0, 13.0])    # 0.3 * A_proj + 0.7 * A_2d


def test_backprojection_inverts_projection():
    depth = np.zeros((100, 200), np.float32)
    depth[40, 70] = 10.0
    p = CAM.backproject_depth(depth)
    assert np.allclose(CAM.project(p), [[70.5, 40.5]])     # the pixel's centre


def test_from_dict_accepts_a_calibrated_K():
    d = CAM.to_dict()
    assert d["calibrated"] is True
    assert Camera.from_dict(d) == CAM
    only_k = {"width": 200, "height": 100, "K": [[100, 0, 60], [0, 50, 30], [0, 0, 1]]}
    assert Camera.from_dict(only_k) == CAM
    eq1 = Camera.from_fov(200, 100, 60.0)
    assert Camera.from_dict(eq1.to_dict()) == eq1 and "calibrated" not in eq1.to_dict()
    bad = eq1.to_dict()
    bad["K"][0][2] += 5                                      # angles and a disagreeing K, unmarked
    with pytest.raises(ValueError, match="disagrees"):
        Camera.from_dict(bad)
    with pytest.raises(ValueError, match="skew"):
        Camera.from_K(200, 100, [[100, 1, 60], [0, 50, 30], [0, 0, 1]])


def test_eq1_camera_is_unchanged():
    cam = Camera.from_fov(640, 480, 45.0)
    assert cam.cx == 320 and cam.cy == 240
    assert cam.tan_half[0] == pytest.approx(np.tan(np.radians(22.5)))


def test_distortion_is_undone_on_images():
    cam = Camera.from_intrinsics(200, 100, 100.0, 100.0, 100.0, 50.0, dist=[-0.3, 0.1, 0.0, 0.0])
    assert Camera.from_dict(cam.to_dict()) == cam
    img = np.zeros((100, 200, 3), np.uint8)
    img[:, ::10] = 255                                        # vertical lines bend under distortion
    und = cam.undistort_image(img)
    assert und.shape == img.shape and not np.array_equal(und, img)
    assert np.array_equal(und[50, 95:106], img[50, 95:106])   # the centre stays put
    assert Camera.from_intrinsics(200, 100, 100.0, 100.0, 100.0, 50.0, dist=[0, 0, 0, 0]).dist is None
    from track3d.tracker import Track3D

    t = Track3D.create(cam, "kcf", "baseline")
    t.init(img, [90, 40, 20, 20], 0)
    assert t.update(img, np.zeros((0, 3), np.float32)).status in ("no_points", "lost")


@pytest.mark.parametrize("change, message", [
    ({"width": 200.7}, "whole number of pixels"),         # was truncated to 200 without a word
    ({"height": "100"}, "whole number of pixels"),
    ({"width": True}, "whole number of pixels"),
    ({"K": [[100, 0], [0, 50]]}, r"3x3 matrix, got shape \(2, 2\)"),   # was numpy's broadcast message
    ({"K": [[100, 0, 60], [0, 50]]}, "3x3 matrix of numbers"),
    ({"K": [[100, 0, float("nan")], [0, 50, 30], [0, 0, 1]]}, "NaN or inf"),
])
def test_from_dict_names_a_bad_resolution_or_K(change, message):
    for base in (CAM.to_dict(), Camera.from_fov(200, 100, 60.0).to_dict()):
        with pytest.raises(ValueError, match=message):
            Camera.from_dict({**base, **change})


@pytest.mark.parametrize("w, h", [(0, 0), (0, 10), (10, 0), (-4, 3)])
def test_from_fov_refuses_an_empty_image(w, h):
    with pytest.raises(ValueError, match="resolution must be positive"):   # was ZeroDivisionError for w = 0
        Camera.from_fov(w, h, 40.0)


@pytest.mark.parametrize("make", [
    lambda w: Camera(w, 100, 45.0, 30.0),                           # kept 640.5 as the width
    lambda w: Camera.from_fov(w, 100, 45.0),                        # truncated to 640
    lambda w: Camera.from_intrinsics(w, 100, 100.0, 50.0, 60.0, 30.0),
])
@pytest.mark.parametrize("width", [640.5, "640", True])
def test_every_constructor_wants_whole_pixels(make, width):
    with pytest.raises(ValueError, match="whole number of pixels"):
        make(width)
    assert make(np.int64(640)).width == 640 and type(make(640.0).width) is int


@pytest.mark.parametrize("bad", [(float("nan"), 600.0, 320.0, 240.0), (600.0, 600.0, float("inf"), 240.0),
                                 (600.0, 600.0, 320.0, float("nan"))])
def test_non_finite_intrinsics_are_named(bad):
    # fx = nan had been told "camera fov_x_deg must be in (0, 180)", cx = inf was taken
    with pytest.raises(ValueError, match="must be finite"):
        Camera.from_intrinsics(640, 480, *bad)


def test_a_calibrated_camera_has_no_baseline_unless_given_and_stereo_refuses_it():
    """from_intrinsics / from_K had defaulted baseline_m to the simulator's 0.4 m: a 12 cm rig's
    stereo depth came out 3.3 times too far, "tracking", without a word. Now None (no pair),
    and the stereo matcher names what it needs; a baseline of 0, < 0 or nan, which had failed
    deep in OpenCV (an assertion, an 18 EB allocation), is refused by the camera."""
    from track3d.stereo import StereoCloud, StereoMatcher

    cam = Camera.from_intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0)
    assert cam.baseline_m is None
    assert Camera.from_K(640, 480, cam.K).baseline_m is None
    with pytest.raises(ValueError, match="baseline"):
        StereoMatcher(cam)
    with pytest.raises(ValueError, match="baseline"):
        StereoCloud(cam)
    with pytest.raises(ValueError, match="baseline"):
        cam.disparity(10.0)
    assert Camera.from_dict(cam.to_dict()) == cam                  # None survives the file
    given = Camera.from_intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0, baseline_m=0.12)
    assert StereoMatcher(given).fb == pytest.approx(72.0)
    assert Camera.from_dict(given.to_dict()) == given
    assert Camera.from_fov(640, 480, 45.0).baseline_m == 0.4        # the simulator's camera
    for bad in (0.0, -0.4, float("nan"), float("inf"), "x"):
        with pytest.raises(ValueError, match="baseline_m"):
            Camera.from_intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0, baseline_m=bad)
        with pytest.raises(ValueError, match="baseline_m"):
            Camera.from_fov(640, 480, 45.0, baseline_m=bad)
    with pytest.raises(ValueError, match="rectified"):
        StereoMatcher(Camera.from_intrinsics(640, 480, 600.0, 600.0, 320.0, 240.0, dist=[0.1, 0, 0, 0],
                                             baseline_m=0.12))
