"""Labels of the simulator are right (they are checked against the rendered geometry)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")

from track3d.dataset import Dataset  # noqa: E402

from track3d_sim.generate import camera_of, generate, make_settings  # noqa: E402
from track3d_sim.sequence import plan, render_sequence  # noqa: E402


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "tiny"
    settings = make_settings("tiny", seed=3, frames=10)
    generate(settings, out, workers=1, progress=False, log=lambda m: None)
    return Dataset(out), settings


def _frames(data):
    for split in ("train", "test"):
        for seq in data.sequences(split):
            for i in range(len(seq)):
                yield seq, i, seq.frame(i, right=True)


def test_reader_reads_everything(tiny):
    data, settings = tiny
    assert len(data.splits["train"]) == settings["train"] and len(data.splits["test"]) == settings["test"]
    assert data.camera.width == settings["width"] and data.camera.fx == pytest.approx(data.camera.fy)
    info = data.info
    assert len(info["categories"]["fine"]) == 6 * len(info["categories"]["generators"]) and len(info["size_classes"]) == 14
    assert not set(info["categories"]["train_fine"]) & set(info["categories"]["test_fine"])
    cats = {split: {s.meta["fine_category"] for s in data.sequences(split)} for split in ("train", "test")}
    assert not cats["train"] & cats["test"]
    for seq in data.sequences("train"):
        assert len(seq) == settings["frames"]
        assert seq.meta["family_index"] in (0, 1, 2)


def test_depth_points_inside_3d_box(tiny):
    data, _ = tiny
    n_pts = 0
    for seq, i, fr in _frames(data):
        b = fr.box3d
        lo, hi = b[:3] - b[3:] / 2, b[:3] + b[3:] / 2
        p = fr.points
        n_pts += len(p)
        assert np.all(p >= lo - 1e-3) and np.all(p <= hi + 1e-3), f"{seq.name}#{i}: depth point outside 3D box"
        assert np.all(p[:, 2] >= 1.0) and np.all(p[:, 2] <= 45.0)
    assert n_pts > 1000


def test_2d_box_is_bounds_of_object_pixels(tiny):
    data, _ = tiny
    n_absent = 0
    for seq, i, fr in _frames(data):
        vv, uu = np.nonzero(fr.depth_m > 0)
        if fr.absent:
            n_absent += 1
            assert len(uu) == 0
            continue
        assert len(uu) > 0, f"{seq.name}#{i}: not absent but no object pixel"
        expect = [uu.min(), vv.min(), uu.max() + 1 - uu.min(), vv.max() + 1 - vv.min()]
        np.testing.assert_array_equal(fr.box2d, expect)
        touches = uu.min() == 0 or vv.min() == 0 or uu.max() == data.camera.width - 1 or vv.max() == data.camera.height - 1
        if touches:
            assert fr.cut, f"{seq.name}#{i}: silhouette at the border but not flagged cut"


def test_backprojection_reproduces_rendered_points(tiny):
    data, settings = tiny
    cam = camera_of(settings)
    spec = plan(settings["train"], settings["test"])[0]
    res = render_sequence(spec, settings, cam, None, keep_right_depth=True)
    seq = data.sequence("train", spec.name)
    np.testing.assert_array_equal(seq.gt2d, res["gt2d"])
    rays = cam.pixel_rays()
    for i in range(len(seq)):
        depth = seq.depth(i)
        pts = seq.points(i)
        vv, uu = np.nonzero(depth > 0)
        # exact hit points of this frame from a fresh render (z in metres, not rounded to mm)
        z = _left_depth(res, i, spec, settings, cam)
        exact = rays[vv, uu] * z[vv, uu, None]
        assert np.abs(pts - exact).max() < 1.5e-3
        # and the points project back onto their own pixel centres
        uv = cam.project(pts)
        np.testing.assert_allclose(uv, np.stack([uu + 0.5, vv + 0.5], 1), atol=1e-3)


def _left_depth(res, i, spec, settings, cam):
    from track3d_sim.render import BodyRenderer
    from track3d_sim.textures import SolidTexture
    shape = res["shape"]
    R = np.asarray(res["meta"]["frame_data"]["R"][i]).reshape(3, 3)
    T = np.asarray(res["meta"]["frame_data"]["T"][i])
    r = BodyRenderer(shape, SolidTexture(0, np.random.default_rng(0), shape.vertices), cam)
    return r.cast(R, T)["z"]


def test_right_disparity_matches_depth(tiny):
    data, settings = tiny
    cam = camera_of(settings)
    checked = 0
    for spec in plan(settings["train"], settings["test"])[:3]:
        res = render_sequence(spec, settings, cam, None, keep_right_depth=True)
        seq = data.sequence(spec.split, spec.name)
        for i in range(len(seq)):
            zl = seq.depth(i).astype(np.float64)
            zr = res["right_depth"][i]
            vv, uu = np.nonzero(zl > 0)
            if len(uu) < 50:
                continue
            d = cam.fx * cam.baseline_m / zl[vv, uu]
            ur = np.floor(uu + 0.5 - d).astype(int)
            ok = (ur >= 0) & (ur < cam.width)
            zr_at = zr[vv[ok], ur[ok]]
            agree = np.abs(zr_at - zl[vv[ok], uu[ok]]) < 0.01 * zl[vv[ok], uu[ok]] + 0.02
            assert agree.mean() > 0.85, f"{spec.name}#{i}: right view disagrees with d = fx*0.4/z"
            # the object moved left in the right image by the disparity: the unshifted pixel is worse
            same = np.abs(zr[vv[ok], uu[ok]] - zl[vv[ok], uu[ok]]) < 0.01 * zl[vv[ok], uu[ok]] + 0.02
            if d.mean() > 3:
                assert agree.mean() > same.mean()
            checked += 1
    assert checked > 5
