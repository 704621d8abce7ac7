"""2D tracker registry and adapters."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from track3d import trackers2d as T


def _image(x=50, y=40, w=40, h=30, size=(120, 160)):
    im = np.zeros((*size, 3), np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    im[y:y + h, x:x + w] = (60 + 150 * (((xx // 5) + (yy // 5)) % 2))[..., None].astype(np.uint8)
    return im


def test_registry_lists_the_builtin_names():
    names = T.available_trackers()
    for n in ("oracle", "kcf", "csrt", "mosse", "mil", "medianflow", "boosting", "nano",
              "siamfc", "siamfc-edge"):
        assert n in names


@pytest.mark.parametrize("name", ["kcf", "csrt", "mosse", "mil", "medianflow", "boosting"])
def test_opencv_adapters_follow_a_moving_patch(name):
    tr = T.create_tracker(name)
    assert isinstance(tr, T.Tracker2D)
    tr.init(_image(), np.array([50, 40, 40, 30]))
    ok, box = tr.update(_image(x=53, y=41))
    assert isinstance(ok, bool) and box.shape == (4,) and box.dtype == np.float64
    if ok and name in ("kcf", "csrt"):  # the others are checked for the adapter only
        assert abs(box[0] - 53) < 12 and abs(box[1] - 41) < 12


def test_opencv_adapter_box_outside_the_image_is_lost_not_a_crash():
    tr = T.create_tracker("kcf")
    tr.init(_image(), np.array([500.0, 500.0, 20.0, 20.0]))
    ok, box = tr.update(_image())
    assert ok is False and box.shape == (4,)
    tr.init(_image(), np.array([np.nan, 0.0, 20.0, 20.0]))
    assert tr.update(_image())[0] is False


def test_opencv_adapter_checks_images_and_boxes():
    tr = T.create_tracker("kcf")
    with pytest.raises(ValueError, match="uint8"):
        tr.init(np.zeros((10, 10), np.uint8), [0, 0, 5, 5])
    with pytest.raises(ValueError, match="box"):
        tr.init(_image(), [0, 0, 5])
    with pytest.raises(ValueError, match="correct"):
        T.create_tracker("kcf", correct="sometimes")


def test_reinit_correction_moves_the_state():
    tr = T.create_tracker("kcf", correct="reinit")
    tr.init(_image(), np.array([50, 40, 40, 30]))
    tr.update(_image())
    tr.correct(np.array([52.0, 41.0, 40.0, 30.0]))
    ok, box = tr.update(_image(x=52, y=41))
    assert ok and abs(box[0] - 52) <= 3


def test_register_and_unknown_names():
    class Still:
        def init(self, image, box):
            self.box = np.asarray(box, float)

        def update(self, image):
            return True, self.box

    T.register_tracker("still-test", lambda **kw: Still())
    try:
        tr = T.create_tracker("STILL-TEST")
        tr.init(_image(), [1, 2, 3, 4])
        assert tr.update(_image())[1].tolist() == [1, 2, 3, 4]
    finally:
        T._REGISTRY.pop("still-test")
    with pytest.raises(ValueError, match="unknown 2D tracker 'nope'"):
        T.create_tracker("nope")


def test_siamfc_is_built_or_clearly_unavailable():
    for name in ("siamfc", "siamfc-edge"):
        try:
            tr = T.create_tracker(name)
        except T.TrackerUnavailable as e:
            assert "SiamFC model not available" in str(e)
        else:
            assert hasattr(tr, "init") and hasattr(tr, "update")


def test_nano_with_missing_files_is_a_clear_error(tmp_path):
    with pytest.raises(T.TrackerUnavailable, match="NanoTrack model file"):
        T.create_tracker("nano", backbone=tmp_path / "a.onnx", neckhead=tmp_path / "b.onnx")


@pytest.mark.skipif(T.nanotrack_dir() is None or not (T.nanotrack_dir() / "nanotrack_backbone_sim.onnx").is_file(),
                    reason="peer models absent (set TRACK3D_NANOTRACK_DIR)")
def test_nano_peer_runs(capfd):
    tr = T.create_tracker("nano")
    tr.init(_image(), np.array([50, 40, 40, 30]))
    ok, box = tr.update(_image(x=52))
    assert box.shape == (4,)
    # OpenCV's warning about its DNN target, once per creation, is not the user's business
    assert "setPreferableTarget" not in capfd.readouterr().err


def test_opencv_log_level_is_restored_after_the_block():
    levels = cv2.utils.logging
    before = levels.getLogLevel()
    with T.opencv_log_level(levels.LOG_LEVEL_SILENT):
        assert levels.getLogLevel() == levels.LOG_LEVEL_SILENT
    assert levels.getLogLevel() == before
    with pytest.raises(RuntimeError):
        with T.opencv_log_level(levels.LOG_LEVEL_SILENT):
            raise RuntimeError("inside")
    assert levels.getLogLevel() == before


def test_nanotrack_without_its_peer_models_is_unavailable(monkeypatch):
    monkeypatch.delenv(T.NANOTRACK_ENV, raising=False)
    with pytest.raises(T.TrackerUnavailable, match="TRACK3D_NANOTRACK_DIR"):
        T.create_tracker("nano")


def test_a_degenerate_candidate_is_penalised_without_a_warning():
    """A zero-size candidate box (ratio 0) used to divide by zero (RuntimeWarning in the fuzz run)."""
    import warnings

    from track3d.edgetrack import _change

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = _change(np.array([0.0, 0.5, 1.0, 2.0]))
    assert np.all(np.isfinite(c)) and c[0] >= 1e12
    np.testing.assert_allclose(c[1:], [2.0, 1.0, 2.0])
