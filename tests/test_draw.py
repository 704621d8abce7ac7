"""track3d.evaluation.draw: the overlay frames `track3d track` writes."""
import numpy as np

from track3d.camera import Camera
from track3d.evaluation.draw import BOX3D, FUSED, GT, RAW, draw_overlay

CAM = Camera.from_fov(320, 240, 45.0)


def _has(img: np.ndarray, colour) -> bool:
    return bool(np.any(np.all(img == np.array(colour, np.uint8), axis=-1)))


def test_the_overlay_carries_a_key_of_the_boxes_drawn():
    blank = np.zeros((240, 320, 3), np.uint8)
    box = np.array([100.0, 60.0, 60.0, 40.0])
    cube = np.array([0.0, 0.0, 20.0, 2.0, 2.0, 2.0])
    full = draw_overlay(blank, CAM, box, box + 3, cube, box - 3, cube)
    key_rows = full[-20:]   # the boxes lie far above: what is drawn here is the key
    for colour in (GT, RAW, FUSED, BOX3D):
        assert _has(key_rows, colour), colour
    only_truth = draw_overlay(blank, CAM, gt2d=box)[-20:]
    assert _has(only_truth, GT) and not _has(only_truth, FUSED) and not _has(only_truth, BOX3D)
    assert not draw_overlay(blank, CAM)[-20:].any()   # nothing drawn, no key
    # the loop passes nan boxes where it has none (a 2D-only run's 3D box, a skipped frame's):
    # not drawn, so not in the key
    nan4, nan6 = np.full(4, np.nan), np.full(6, np.nan)
    two_d = draw_overlay(blank, CAM, box, box + 3, nan6, box - 3, nan6)[-20:]
    assert _has(two_d, FUSED) and not _has(two_d, BOX3D)
    skipped = draw_overlay(blank, CAM, nan4, nan4, nan6, box, cube)[-20:]
    assert _has(skipped, GT) and not _has(skipped, FUSED) and not _has(skipped, RAW)
    assert not blank.any()                            # the caller's image untouched
