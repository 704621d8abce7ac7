"""Texture the stereo depth did not match (track3d.unmatched_texture) and its use in the loop."""
from __future__ import annotations

import numpy as np
import pytest

from track3d.boxes import iou_2d
from track3d.camera import Camera
from track3d.unmatched_texture import MATCH_COVER, trim_unmatched

CAM = Camera.from_fov(160, 120, 45.0)
LIT = np.array([100.0, 50.0, 80.0, 80.0])     # the lit outline: pixels x 100..179, y 50..129


def _texture(rng, shape) -> np.ndarray:
    return rng.integers(20, 90, size=shape).astype(np.uint8)


def _scene(moon: tuple[slice, slice] | None = None, glow: bool = False, seed: int = 0) -> np.ndarray:
    """(200, 300, 3) uint8: black sky, the body's textured lit part at LIT, and optionally a
    textured moon at the given rows and columns or a smooth glow left of the body (0 DN at x 0
    rising to 70 DN at x 99), both without depth."""
    rng = np.random.default_rng(seed)
    img = np.zeros((200, 300, 3), np.uint8)
    img[50:130, 100:180] = _texture(rng, (80, 80, 1))
    if moon is not None:
        img[moon] = _texture(rng, (moon[0].stop - moon[0].start, moon[1].stop - moon[1].start, 1))
    if glow:
        img[:, :100] = np.linspace(0.0, 70.0, 100).astype(np.uint8)[None, :, None]
    return img


def test_a_box_spread_over_a_moon_is_pulled_in_to_it():
    """A moon left of the body, 5 dark columns apart (x 60..94): the box reaching to x 40 ends
    where the moon's texture starts, seen from the body: column 96's 5 x 5 block holds the moon's
    column 94, column 97's does not, so the left side is 97. Its other sides stay."""
    img = _scene(moon=(slice(40, 140), slice(60, 95)))
    box = np.array([40.0, 45.0, 145.0, 90.0])
    out = trim_unmatched(box, LIT, img, returns=6400)
    np.testing.assert_allclose(out, [97.0, 45.0, 185.0 - 97.0, 90.0])
    # the same moon right of the body (x 185..219), and below it (y 135..169)
    img = _scene(moon=(slice(40, 140), slice(185, 220)))
    out = trim_unmatched(np.array([95.0, 45.0, 140.0, 90.0]), LIT, img, returns=6400)
    np.testing.assert_allclose(out, [95.0, 45.0, 183.0 - 95.0, 90.0])   # column 183's block reaches 185
    img = _scene(moon=(slice(135, 170), slice(90, 190)))
    out = trim_unmatched(np.array([95.0, 45.0, 90.0, 140.0]), LIT, img, returns=6400)
    np.testing.assert_allclose(out, [95.0, 45.0, 90.0, 133.0 - 45.0])
    # and above it (y 10..44)
    img = _scene(moon=(slice(10, 45), slice(90, 190)))
    out = trim_unmatched(np.array([95.0, 5.0, 90.0, 130.0]), LIT, img, returns=6400)
    np.testing.assert_allclose(out, [95.0, 47.0, 90.0, 135.0 - 47.0])


def test_a_dark_side_a_glow_and_a_dark_body_keep_the_box():
    box = np.array([40.0, 45.0, 145.0, 90.0])
    # dark beyond the outline (the body's dark side, or sky): the box as it was
    np.testing.assert_array_equal(trim_unmatched(box, LIT, _scene(), returns=6400), box)
    # a smooth glow (stray light, glare, a nebula's) is not texture
    img = _scene(glow=True)
    out = trim_unmatched(box, LIT, img, returns=6400)
    np.testing.assert_array_equal(out, box)
    # a moon beside a body whose own texture is mostly unmatched (few returns): no rule
    img = _scene(moon=(slice(40, 140), slice(60, 95)))
    few = int(MATCH_COVER * 6400) - 200
    np.testing.assert_array_equal(trim_unmatched(box, LIT, img, returns=few), box)
    # the moon within the right camera's blind band at the left border: no depth could be there
    np.testing.assert_array_equal(trim_unmatched(box, LIT, img, returns=6400, blind_px=98.0), box)
    # a box that does not reach past the outline, a box wholly outside the image: as they were
    np.testing.assert_array_equal(trim_unmatched(LIT + [-1, -1, 2, 2], LIT, img, 6400), LIT + [-1, -1, 2, 2])
    np.testing.assert_array_equal(trim_unmatched(LIT + [-2000, 0, 3000, 0], LIT + [-2000, 0, 0, 0], img, 6400),
                                  LIT + [-2000, 0, 3000, 0])


def test_the_loop_pulls_a_stereo_box_off_a_moon_and_records_the_option(tmp_path):
    """A 2D tracker that spread its box over a textured moon beside the body (EdgeTrack on a
    held-out stereo sequence: IoU_2d 0.93 -> 0.75): with `texture_trim` the contained box ends
    where the moon's texture starts, and the tracker is corrected with that box; off, the box
    keeps the moon. On for stereo by the sensor table, recorded when on, checked."""
    from track3d.estimators import create_estimator
    from track3d.evaluation import TrackerSpec
    from track3d.tracker import Track3D
    from track3d.sensor_options import sensor_options, texture_trim_for
    from test_silhouette import _losing

    body = np.zeros((120, 160), bool)
    body[40:80, 80:130] = True                     # the body: returns on x 80..129, y 40..79
    rows, cols = np.indices(body.shape)
    pts = CAM.backproject_depth(np.where(body, 10.0 + 0.05 * ((rows + cols) % 5), 0.0).astype(np.float32))
    rng = np.random.default_rng(3)
    image = np.zeros((120, 160, 3), np.uint8)
    image[40:80, 80:130] = _texture(rng, (40, 50, 1))
    image[35:85, 40:74] = _texture(rng, (50, 34, 1))   # the moon: x 40..73, no depth
    spread = [42.0, 40.0, 88.0, 40.0]              # the tracker's box: over the moon and the body

    def run(trim):
        Tracker = _losing(spread)
        Tracker.update = lambda self, image: (True, np.array(spread))
        tr = Tracker()
        t = Track3D(CAM, tr, create_estimator("baseline"), silhouette=0.0, outline_share=0.3,
                    outline_contain=True, weight_3d=0.15, texture_trim=trim)
        t.init(image, [80.0, 40.0, 50.0, 40.0], points=pts)
        return t.update(image, pts), tr.corrected, t

    off, _, t_off = run(False)
    on, onto, t_on = run(True)
    truth = [80.0, 40.0, 50.0, 40.0]
    assert off.box2d[0] < 60.0 and iou_2d(off.box2d, truth) < 0.75          # the failure: the moon kept
    assert on.box2d[0] > 70.0 and iou_2d(on.box2d, truth) > 0.85
    np.testing.assert_allclose(onto, on.box2d)                              # the tracker corrected with it
    assert t_on.describe()["options"]["texture_trim"] is True
    assert "texture_trim" not in t_off.describe()["options"]
    with pytest.raises(ValueError, match="texture_trim must be True or False"):
        Track3D(CAM, _losing(spread)(), create_estimator("baseline"), texture_trim=1)
    assert texture_trim_for("stereo") is True and texture_trim_for("ideal") is texture_trim_for(None) is False
    assert sensor_options("stereo")["texture_trim"] is True
    from test_loop import _plain_and
    _, tof = _plain_and(tmp_path, {"name": "tof", "max_range_m": 30.0})
    assert TrackerSpec("oracle", "baseline").build(tof).texture_trim is False
    assert TrackerSpec("oracle", "baseline", texture_trim=True).build(tof).texture_trim is True


def test_a_trimmed_box_stays_within_the_box_and_holds_the_outline():
    """Any image, box and outline (seeded draws, boxes often past the image border): the answer
    is finite, inside the box, and still holds the outline shrunk by the slack."""
    rng = np.random.default_rng(11)
    for _ in range(300):
        img = rng.integers(0, 256, size=(int(rng.integers(8, 90)), int(rng.integers(8, 90)), 3)).astype(np.uint8)
        if rng.random() < 0.5:
            img[:, : img.shape[1] // 2] = 0          # half dark
        H, W = img.shape[:2]
        lit = np.array([rng.uniform(-20, W), rng.uniform(-20, H), rng.uniform(1, W), rng.uniform(1, H)])
        grow = rng.uniform(0, 30, size=4)
        box = lit + [-grow[0], -grow[1], grow[0] + grow[2], grow[1] + grow[3]]
        out = trim_unmatched(box, lit, img, returns=int(rng.integers(0, 5000)), blind_px=float(rng.uniform(0, 20)))
        assert out.shape == (4,) and np.all(np.isfinite(out))
        assert out[0] >= box[0] and out[1] >= box[1]
        assert out[0] + out[2] <= box[0] + box[2] + 1e-9 and out[1] + out[3] <= box[1] + box[3] + 1e-9
        assert out[0] <= lit[0] - 2.0 + 1e-9 or out[0] == box[0]
        assert out[1] <= lit[1] - 2.0 + 1e-9 or out[1] == box[1]
        right, bottom = out[0] + out[2], out[1] + out[3]
        assert right >= lit[0] + lit[2] + 2.0 - 1e-9 or right == box[0] + box[2]
        assert bottom >= lit[1] + lit[3] + 2.0 - 1e-9 or bottom == box[1] + box[3]


def test_an_axis_left_as_it_was_keeps_its_numbers():
    """x + w - x is not always w in floats: a box the rule leaves alone on an axis comes back
    with that axis's very numbers ((9.75311907905558 + 54.69118559223883) - 9.75311907905558 is
    not 54.69118559223883)."""
    x, w = 9.75311907905558, 54.69118559223883
    assert (x + w) - x != w
    rng = np.random.default_rng(1)
    img = np.zeros((100, 100, 3), np.uint8)
    img[20:50, 20:50] = _texture(rng, (30, 30, 1))
    lit = np.array([20.0, 20.0, 30.0, 30.0])
    box = np.array([x, x, w, w])                   # past the outline on every side, over dark sky
    np.testing.assert_array_equal(trim_unmatched(box, lit, img, returns=900), box)
    img[10:60, 55:70] = _texture(rng, (50, 15, 1))  # a moon right of the body: only x moves
    out = trim_unmatched(box, lit, img, returns=900)
    assert out[0] == x and out[0] + out[2] == 53.0 and out[1] == x and out[3] == w
