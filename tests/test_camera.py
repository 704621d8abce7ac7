import math

import numpy as np
import pytest

from track3d.camera import Camera


def test_intrinsics_match_paper_eq1_hand_computed():
    # 90 deg horizontal FOV on 640 px: tan(45) = 1 -> fx = 640 / 2 = 320.
    cam = Camera(640, 480, 90.0, 2 * math.degrees(math.atan(0.75)))
    assert cam.fx == pytest.approx(320.0)
    assert cam.fy == pytest.approx(320.0)  # tan(ay/2) = 0.75 -> 480 / 1.5
    assert (cam.cx, cam.cy) == (320.0, 240.0)
    np.testing.assert_allclose(cam.M, [[320, 0, 320, 0], [0, 320, 240, 0], [0, 0, 1, 0]])


def test_from_fov_gives_square_pixels():
    cam = Camera.from_fov(640, 480, 45.0)
    assert cam.fx == pytest.approx(cam.fy)


def test_project_hand_case():
    cam = Camera(640, 480, 90.0, 2 * math.degrees(math.atan(0.75)))
    uv = cam.project(np.array([[1.0, -0.5, 2.0], [0.0, 0.0, 5.0]]))
    np.testing.assert_allclose(uv, [[320 + 160, 240 - 80], [320, 240]])


def test_backprojection_inverts_projection_at_pixel_centres():
    cam = Camera.from_fov(64, 48, 50.0)
    rng = np.random.default_rng(0)
    depth = rng.uniform(1, 40, size=(48, 64)).astype(np.float32)
    depth[5, 7] = 0.0  # no return
    pts = cam.backproject_depth(depth)
    assert pts.shape == (64 * 48 - 1, 3) and pts.dtype == np.float32
    uv = cam.project(pts)
    vv, uu = np.nonzero(depth > 0)
    np.testing.assert_allclose(uv[:, 0], uu + 0.5, atol=1e-3)
    np.testing.assert_allclose(uv[:, 1], vv + 0.5, atol=1e-3)


def test_backproject_rejects_wrong_shape():
    cam = Camera.from_fov(64, 48, 50.0)
    with pytest.raises(ValueError, match="shape"):
        cam.backproject_depth(np.ones((10, 10)))


def test_section_projection_hand_case():
    cam = Camera(640, 480, 90.0, 2 * math.degrees(math.atan(0.75)))
    # A 2 m x 1 m section centred on the axis at 4 m: 320 * 2 / 4 = 160 px wide, 80 px high.
    np.testing.assert_allclose(cam.project_box3d_section([0, 0, 4, 2, 1, 3]), [240, 200, 160, 80])
    assert np.all(np.isnan(cam.project_box3d_section([0, 0, -1, 1, 1, 1])))


def test_dict_roundtrip_and_validation():
    cam = Camera.from_fov(320, 240, 40.0)
    assert Camera.from_dict(cam.to_dict()) == cam
    bad = cam.to_dict()
    bad["K"][0][0] += 5
    with pytest.raises(ValueError, match="disagrees"):
        Camera.from_dict(bad)
    with pytest.raises(ValueError):
        Camera(0, 10, 40, 30)
    with pytest.raises(ValueError):
        Camera(10, 10, 180, 30)
