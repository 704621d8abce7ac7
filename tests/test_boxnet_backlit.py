"""Bodies lit from behind get a model of their own (track3d.boxnet.BACKLIT_MODELS): the estimator
runs it past `backlit_phase` degrees of phase, which the loop hands it from the sun's direction."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxnet import (BACKLIT_PHASE_DEG, FULL_WIDTH_MODEL, NARROW_MODEL, STEREO_FULL_WIDTH_MODEL,
                            A3BoxNetEstimator, backlit_model_for)
from track3d.camera import Camera
from track3d.dark_side import phase_deg
from track3d.onnxmodel import ModelError, shipped_model
from track3d.tracker import Track3D
from track3d.trackers2d import OracleTracker

CAM = Camera.from_fov(640, 480, 45.0)


@pytest.fixture(scope="module")
def cloud():
    rng = np.random.default_rng(7)
    p = (rng.normal(size=(2000, 3)) * [1.0, 0.7, 0.5] + [0.4, -0.3, 12.0]).astype(np.float32)
    return p, np.stack([p.min(0), p.max(0)]).astype(np.float64)


@pytest.fixture(scope="module")
def gated():
    """The narrow model for bodies lit from the front, the full-width one past 100 degrees: two
    models that answer differently, so the test sees which one ran."""
    return A3BoxNetEstimator(shipped_model(NARROW_MODEL), backlit_model=shipped_model(FULL_WIDTH_MODEL))


def test_the_gate_picks_the_model_by_phase(cloud, gated):
    pts, b = cloud
    assert gated.takes_phase
    front = A3BoxNetEstimator(shipped_model(NARROW_MODEL)).estimate(pts, -1, b)
    back = A3BoxNetEstimator(shipped_model(FULL_WIDTH_MODEL)).estimate(pts, -1, b)
    assert not np.allclose(front, back)
    assert gated.backlit_phase == BACKLIT_PHASE_DEG == 100.0
    np.testing.assert_array_equal(gated.estimate(pts, -1, b), front)                  # sun unknown
    np.testing.assert_array_equal(gated.estimate(pts, -1, b, phase_deg=None), front)
    np.testing.assert_array_equal(gated.estimate(pts, -1, b, phase_deg=100.0), front)  # at the gate: front
    np.testing.assert_array_equal(gated.estimate(pts, -1, b, phase_deg=100.5), back)
    np.testing.assert_array_equal(gated.estimate(pts, -1, b, phase_deg=150.0), back)
    np.testing.assert_array_equal(gated.estimate(pts, -1, phase_deg=150.0), back)     # bounds computed
    # the run records name both files, by their hashes (Track3D.describe)
    files = [m["file"] for m in Track3D(CAM, OracleTracker(np.zeros((1, 4))), gated).describe()["models"]]
    assert sorted(files) == sorted([NARROW_MODEL, FULL_WIDTH_MODEL])
    assert "backlit=a3boxnet.onnx past 100 deg" in repr(gated)


def test_the_gate_is_optional_and_checked(cloud):
    pts, b = cloud
    front = A3BoxNetEstimator(shipped_model(NARROW_MODEL))
    assert front.backlit is None                       # no sensor, no model given: one model
    assert not front.takes_phase                       # so the loop computes no phase for it
    never = A3BoxNetEstimator(shipped_model(NARROW_MODEL), backlit_model=shipped_model(FULL_WIDTH_MODEL),
                              backlit_phase=180)
    assert never.backlit is None and not never.takes_phase
    np.testing.assert_array_equal(never.estimate(pts, -1, b, phase_deg=170.0), front.estimate(pts, -1, b))
    later = A3BoxNetEstimator(shipped_model(NARROW_MODEL), backlit_model=shipped_model(FULL_WIDTH_MODEL),
                              backlit_phase=120)
    np.testing.assert_array_equal(later.estimate(pts, -1, b, phase_deg=110.0), front.estimate(pts, -1, b))
    for bad in (-1, 181, "x", True, float("nan")):
        with pytest.raises(ValueError, match="backlit_phase must be degrees in 0..180"):
            A3BoxNetEstimator(shipped_model(NARROW_MODEL), backlit_phase=bad)
    for bad in (-0.5, 180.5, float("nan"), float("inf"), "far", True, np.array([120.0, 130.0]), [150.0]):
        with pytest.raises(ValueError, match="phase_deg must be degrees in 0..180 or None"):
            never.estimate(pts, -1, b, phase_deg=bad)   # checked with or without a back-lit model
        with pytest.raises(ValueError, match="phase_deg must be degrees in 0..180 or None"):
            front.estimate(pts, -1, b, phase_deg=bad)
    np.testing.assert_array_equal(front.estimate(pts, -1, b, phase_deg=np.float32(150.0)),
                                  front.estimate(pts, -1, b))
    with pytest.raises(ModelError, match="does not exist"):
        A3BoxNetEstimator(shipped_model(NARROW_MODEL), backlit_model="no/such/model.onnx")


def test_sensors_get_their_backlit_model_unless_a_model_is_named():
    """Stereo depth has a back-lit model (the crescent's depth is the lit limb's); the range
    sensors see the whole near side at any phase and have none; an explicit model wins."""
    for other in (None, "ideal", "tof", "flash-lidar"):
        assert backlit_model_for(other) is None
        assert A3BoxNetEstimator(depth_sensor=other).backlit is None
    stereo = A3BoxNetEstimator(depth_sensor="stereo")
    assert stereo.backlit is not None and stereo.backlit.model.path == backlit_model_for("stereo")
    assert stereo.backlit.backlit is None               # one level: the back-lit model has no gate of its own
    assert A3BoxNetEstimator(shipped_model(NARROW_MODEL), depth_sensor="stereo").backlit is None
    assert A3BoxNetEstimator(depth_sensor="stereo", backlit_phase=180).backlit is None
    assert Track3D.from_default(CAM, depth_sensor="stereo").estimator.backlit is not None
    # the back-lit model is a fine-tune of the full-width stereo model; the loop's is its half-width twin
    assert stereo.backlit.model.meta["trained"]["fine_tuned_from"]["file"] == STEREO_FULL_WIDTH_MODEL
    assert stereo.model.meta["trained"]["distilled_from"]["file"] == STEREO_FULL_WIDTH_MODEL
    # a stereo model named by hand keeps the gate (it dropped it: the full-width stereo model chosen
    # as documented lost the back-lit model without a word); a model of no sensor does not get it
    full = A3BoxNetEstimator(STEREO_FULL_WIDTH_MODEL, depth_sensor="stereo")
    assert full.backlit is not None and full.backlit.model.path == backlit_model_for("stereo")
    assert A3BoxNetEstimator(STEREO_FULL_WIDTH_MODEL, depth_sensor="stereo", backlit_phase=180).backlit is None
    assert A3BoxNetEstimator(STEREO_FULL_WIDTH_MODEL).backlit is None          # no sensor named
    assert A3BoxNetEstimator(shipped_model(FULL_WIDTH_MODEL), depth_sensor="stereo").backlit is None


def test_the_loop_hands_the_phase_at_its_box_only_with_the_sun_known(cloud):
    """Track3D passes phase_deg (track3d.dark_side.phase_deg at the box the frustum is cut with)
    to an estimator with ``takes_phase``, and only once the sun is set; others are called as before."""
    from track3d.boxes import box3d_from_points

    pts, _ = cloud
    uv = CAM.project(pts.astype(np.float64))
    box = np.array([uv[:, 0].min() - 2, uv[:, 1].min() - 2, np.ptp(uv[:, 0]) + 4, np.ptp(uv[:, 1]) + 4])
    image = np.zeros((480, 640, 3), np.uint8)

    class Spy:
        takes_bounds = True
        takes_phase = True

        def __init__(self):
            self.phases = []

        def estimate(self, points, category, bounds=None, phase_deg=None):
            self.phases.append(phase_deg)
            return box3d_from_points(points)

    spy = Spy()
    t = Track3D(CAM, OracleTracker(np.stack([box] * 3)), spy, fusion=False, silhouette=0.0)
    t.init(image, box, points=pts)
    assert spy.phases == [None]
    sun = np.array([0.0, 0.0, 1.0])                      # the sun ahead: a body seen from behind
    t.set_sun(sun)
    t.update(image, pts)
    assert spy.phases[1] == pytest.approx(phase_deg(box, sun, CAM)) and spy.phases[1] > 170.0
    t.set_sun(None)
    t.update(image, pts)
    assert spy.phases[2] is None
