"""EdgeTrack: labels and losses (hand cases), score calibration, training with resume, export +
parity + metadata, and the runtime tracker on a synthetic target that leaves the view and
comes back (a tiny model trained here, on synthetic sequences, in about a minute)."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from track3d.boxes import iou_2d  # noqa: E402
from track3d.onnxmodel import OnnxModel  # noqa: E402
from track3d_train.edgetrack.model import (EdgeTrackConfig, _iou_loss, cell_centres,  # noqa: E402
                                           edgetrack_loss, make_targets)
from track3d_train.edgetrack.train import fit_platt  # noqa: E402

TINY = dict(exemplar_size=128, instance_size=256, lost_instance_size=336, widths=(8, 16, 24, 32),
            feat_channels=32, head_channels=32, head_blocks=1)


# -- labels, losses, calibration: hand cases -----------------------------------------------------
def test_cell_centres_and_targets_hand_case():
    assert cell_centres(3, 16).tolist() == [8.0, 24.0, 40.0]
    # 4x4 map (64 px crop), a 20 x 20 box centred on cell (1, 2): centre (40, 24)
    boxes = torch.tensor([[30.0, 14.0, 50.0, 34.0], [float("nan")] * 4])
    cls, reg_mask, ltrb = make_targets(boxes, 4, 16, 0.5)
    # half axes max(10 * 0.5, 12) = 12: only the centre cell lies within
    assert cls[0].nonzero().tolist() == [[1, 2]]
    assert reg_mask[0].nonzero().tolist() == [[1, 2]]
    assert ltrb[0, :, 1, 2].tolist() == [10.0, 10.0, 10.0, 10.0]
    assert cls[1].sum() == 0 and reg_mask[1].sum() == 0   # negative pair: no target anywhere


def test_iou_loss_hand_case():
    t = torch.tensor([[10.0, 10.0, 10.0, 10.0]])
    assert float(_iou_loss(t, t)) == pytest.approx(0.0, abs=1e-6)
    # 20x20 target, prediction 10x20 inside it: IoU 1/2
    assert float(_iou_loss(torch.tensor([[0.0 + 1e-9, 10.0, 10.0, 10.0]]), t)) == pytest.approx(0.5, abs=1e-6)


def test_loss_is_balanced_and_perfect_logits_cost_nothing():
    cfg = EdgeTrackConfig(**TINY)
    boxes = torch.tensor([[30.0, 14.0, 50.0, 34.0]])
    cls, _, tgt = make_targets(boxes, 8, 16, cfg.pos_radius)
    zero = edgetrack_loss(torch.zeros(1, 1, 8, 8), tgt, boxes, cfg)
    assert float(zero["cls"]) == pytest.approx(math.log(2), rel=1e-5)   # 0.5 log2 + 0.5 log2
    assert float(zero["reg"]) == pytest.approx(0.0, abs=1e-6)
    perfect = edgetrack_loss((cls * 2 - 1)[:, None] * 30, tgt, boxes, cfg)
    assert float(perfect["loss"]) < 1e-6


def test_platt_fit_recovers_a_known_calibration():
    rng = np.random.default_rng(0)
    x = rng.normal(size=20000)
    y = rng.random(20000) < 1 / (1 + np.exp(-(2 * x - 1)))
    a, b = fit_platt(x, y)
    assert a == pytest.approx(2.0, abs=0.1) and b == pytest.approx(-1.0, abs=0.1)
    a, b = fit_platt(np.array([-3.0, -2, 2, 3]), np.array([0, 0, 1, 1]))   # separable: stays finite
    assert 0 < a < 20 and abs(b) < 5


class _ScriptedRng:
    """Stands in for a numpy Generator: integers() -> side, random() -> gone?, uniform() -> f."""

    def __init__(self, side, gone, f):
        self.side, self.gone, self.f = side, gone, f

    def integers(self, n):
        return self.side

    def random(self):
        return 0.0 if self.gone else 0.99

    def uniform(self, lo, hi):
        return self.f


@pytest.mark.parametrize("side, kept, box", [
    (0, (slice(None), slice(0, 105)), [80, 100, 105, 150]),    # padding right of x = 105
    (1, (slice(None), slice(155, None)), [155, 100, 180, 150]),  # left of x = 155
    (2, (slice(0, 113), slice(None)), [80, 100, 180, 112.5]),  # below y = 112.5 (row 112 partly kept)
    (3, (slice(137, None), slice(None)), [80, 137.5, 180, 150]),  # above y = 137.5
])
def test_border_cut_fills_past_the_line_and_clips_the_box(side, kept, box):
    from track3d_train.edgetrack.data import cut_at_border

    crop = np.full((256, 256, 3), 10, np.uint8)
    crop[100:150, 80:180] = 200
    out, b = cut_at_border(crop, np.array([80, 100, 180, 150.0]), _ScriptedRng(side, False, 0.25))
    assert b.tolist() == box                       # a quarter of the 100 x 50 box's extent is left
    colour = crop.reshape(-1, 3).mean(0).round()
    filled = np.ones(crop.shape[:2], bool)
    filled[kept] = False
    assert np.all(out[filled] == colour) and np.array_equal(out[kept], crop[kept])
    assert crop[120, 170, 0] == 200                # the input is not written to


def test_border_cut_before_the_target_is_a_negative_pair():
    from track3d_train.edgetrack.data import cut_at_border

    crop = np.full((64, 64, 3), 10, np.uint8)
    crop[20:40, 20:40] = 200
    out, b = cut_at_border(crop, np.array([20, 20, 40, 40.0]), _ScriptedRng(0, True, -0.25))
    assert b is None and out[:, 15:].max() == out[0, 63].max() and out[25, 10, 0] == 10   # x >= 15 filled


def test_border_cut_fills_with_the_pad_colour():
    from track3d_train.edgetrack.data import PAD, cut_at_border

    crop = np.full((64, 64, 3), 10, np.uint8)
    crop[20:40, 20:40] = 200
    out, b = cut_at_border(crop, np.array([20, 20, 40, 40.0]), _ScriptedRng(0, False, 0.5), PAD)
    assert b.tolist() == [20, 20, 30, 40]
    assert np.all(out[:, 30:] == [255, 0, 255]) and np.array_equal(out[:, :30], crop[:, :30])


def test_prepare_pads_outside_the_image_and_records_the_colour(tmp_path, capsys):
    """Target and background crops reach past the image (a 3x context region): filled with the
    pad colour, recorded in both caches' indexes; the sampler cuts with it, the checkpoint and
    the exported metadata carry it; None ('mean') keeps each frame's mean colour."""
    from track3d_train.cli import main as train_main
    from track3d_train.edgetrack.data import PAD, CropCache, PairSampler, load_background, prepare
    from track3d_train.edgetrack.train import train

    cache = tmp_path / "cache"
    prepare(cache, synthetic=3, synthetic_frames=12, max_frames=36, progress=False)
    assert json.loads((cache / "target" / "index.json").read_text())["pad"] == list(PAD)
    assert json.loads((cache / "background" / "bg.json").read_text())["pad"] == list(PAD)
    crops = np.load(cache / "target" / "crops.npy")
    assert np.all(crops == [255, 0, 255], axis=-1).mean(axis=(1, 2)).max() > 0.05   # near a border
    assert PairSampler(CropCache(cache / "target"), load_background(cache), seed=0).pad == PAD
    train(EdgeTrackConfig(**TINY), cache, tmp_path / "run", steps=1, batch=4, val_every=100, progress=False)
    assert torch.load(str(tmp_path / "run" / "ckpt.pt"), weights_only=False)["pad"] == PAD
    assert train_main(["edgetrack", "export", "--checkpoint", str(tmp_path / "run" / "ckpt.pt"),
                       "--out", str(tmp_path / "m" / "et")]) == 0
    for part in ("template", "search"):
        assert OnnxModel(tmp_path / "m" / f"et_{part}.onnx", 1, f"edgetrack-{part}").meta["pad"] == list(PAD)
    assert train_main(["edgetrack", "prepare", "--synthetic", "2", "--synthetic-frames", "8", "--pad", "mean",
                       "--out", str(tmp_path / "mean"), "--quiet"]) == 0
    assert json.loads((tmp_path / "mean" / "target" / "index.json").read_text())["pad"] is None
    assert not np.any(np.all(np.load(tmp_path / "mean" / "target" / "crops.npy") == [255, 0, 255], axis=-1))
    with pytest.raises(ValueError, match="pad"):
        prepare(tmp_path / "bad", synthetic=1, synthetic_frames=4, progress=False, pad=(300, 0, 0))
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        train_main(["edgetrack", "prepare", "--synthetic", "1", "--pad", "1,2", "--out", str(tmp_path / "b")])
    assert e.value.code == 2 and "--pad" in capsys.readouterr().err


def test_the_runtime_crop_fills_outside_the_image_with_the_models_pad(trained, tmp_path, monkeypatch):
    import shutil

    import track3d.edgetrack as et
    from track3d_train.onnx_meta import rewrite_metadata

    for part in ("template", "search"):
        shutil.copy(trained["root"] / "model" / f"et_{part}.onnx", tmp_path / f"et_{part}.onnx")
    frames, gt, _ = _exit_and_return_sequence()
    seen = []
    real = et.crop_square
    monkeypatch.setattr(et, "crop_square", lambda im, c, sz, out, border: seen.append(border) or real(im, c, sz, out, border))
    tr = et.create(model=tmp_path / "et")                 # no pad in the metadata: the frame's mean colour
    tr.init(frames[0], gt[0])
    tr.update(frames[1])
    assert seen[-1] == pytest.approx(cv2.mean(frames[0])[:3]) and tr.pad is None
    for part in ("template", "search"):
        path = tmp_path / f"et_{part}.onnx"
        meta = OnnxModel(path, 1, f"edgetrack-{part}").meta
        rewrite_metadata(path, {**meta, "pad": [255, 0, 255]})
    tr = et.create(model=tmp_path / "et")
    tr.init(frames[0], gt[0])
    tr.update(frames[1])
    assert seen[-2:] == [(255.0, 0.0, 255.0)] * 2 and tr.get_state()["avg_color"] == [255.0, 0.0, 255.0]
    for bad in ([255, 0], [0, 0, 256], "magenta"):
        meta = OnnxModel(tmp_path / "et_search.onnx", 1, "edgetrack-search").meta
        rewrite_metadata(tmp_path / "et_search.onnx", {**meta, "pad": bad})
        with pytest.raises(ValueError, match="pad must be three values"):
            et.create(model=tmp_path / "et")


def test_sampler_border_cut_share_and_resume_keeps_it(tmp_path, trained):
    from track3d_train.edgetrack.data import CropCache, PairSampler, load_background
    from track3d_train.edgetrack.train import train

    cache = trained["root"] / "cache"
    c = CropCache(cache / "target")
    for share in (0.0, 1.0):
        s = PairSampler(c, load_background(cache), neg_other=0, neg_background=0, seed=1, border_cut=share)
        z, x, boxes = s.sample(64)
        gone = np.isnan(boxes[:, 0]).mean()
        assert (gone == 0) if share == 0 else (0.1 < gone < 0.45)   # CUT_GONE = 0.25 of the cut pairs
    cfg = EdgeTrackConfig(**TINY)
    train(cfg, cache, tmp_path / "r", steps=2, batch=4, val_every=100, border_cut=0.5, progress=False)
    train(cfg, cache, tmp_path / "r", steps=3, batch=4, val_every=100, progress=False)   # resumed
    assert torch.load(str(tmp_path / "r" / "ckpt.pt"), weights_only=False)["border_cut"] == 0.5


# -- training, export, runtime -------------------------------------------------------------------
@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny EdgeTrack trained on synthetic sequences, exported to ONNX."""
    from track3d_train.edgetrack.data import prepare
    from track3d_train.edgetrack.export import export_onnx
    from track3d_train.edgetrack.train import load_checkpoint, train

    root = tmp_path_factory.mktemp("edgetrack")
    # the frame's mean colour outside the image: the runtime tests' expectations were measured
    # with this tiny model (the pad colour has its own test)
    info = prepare(root / "cache", synthetic=10, synthetic_frames=24, max_frames=400, exemplar_size=128,
                   instance_size=256, progress=False, pad=None)
    assert info["target_crops"] > 100 and info["background_crops"] > 0
    cfg = EdgeTrackConfig(**TINY)
    summary = train(cfg, root / "cache", root / "run", steps=150, batch=16, lr=5e-3, val_every=50,
                    progress=False)
    net, ck = load_checkpoint(root / "run" / "ckpt.pt")
    pz, px = export_onnx(net, root / "model" / "et", {"training": {"steps": ck["step"]}})
    return {"root": root, "summary": summary, "net": net, "pz": pz, "px": px}


def test_training_lowers_the_loss_and_writes_curves(trained):
    run = trained["root"] / "run"
    rows = [json.loads(l) for l in (run / "log.jsonl").read_text().splitlines()]
    tr = [r["loss"] for r in rows if r["kind"] == "train"]
    va = [r for r in rows if r["kind"] == "val"]
    assert np.mean(tr[-3:]) < 0.7 * np.mean(tr[:3]), tr
    assert len(va) == 3 and va[-1]["loss"] < va[0]["loss"]
    assert (run / "curves.png").is_file() and json.loads((run / "curves.json").read_text())["val"]
    assert trained["summary"]["step"] == 150


def test_training_resumes_from_its_checkpoint(tmp_path, trained):
    from track3d_train.edgetrack.train import train

    cache = trained["root"] / "cache"
    cfg = EdgeTrackConfig(**TINY)
    s1 = train(cfg, cache, tmp_path / "r", steps=4, batch=4, val_every=100, progress=False)
    ck = torch.load(str(tmp_path / "r" / "ckpt.pt"), weights_only=False)
    assert s1["step"] == 4 and ck["step"] == 4 and not (tmp_path / "r" / "ckpt.pt.tmp").exists()
    s2 = train(cfg, cache, tmp_path / "r", steps=6, batch=4, val_every=100, progress=False)
    assert s2["step"] == 6
    steps = [json.loads(l)["step"] for l in (tmp_path / "r" / "log.jsonl").read_text().splitlines()
             if json.loads(l)["kind"] == "train"]
    assert steps == [4, 6]          # one log across the interruption, no step repeated
    # a kill after logging step 7 but before its checkpoint: the resumed run logs step 7 once
    with open(tmp_path / "r" / "log.jsonl", "a") as f:
        f.write(json.dumps({"kind": "train", "step": 7, "loss": 1.0}) + "\n")
    train(cfg, cache, tmp_path / "r", steps=7, batch=4, val_every=100, progress=False)
    steps = [json.loads(l)["step"] for l in (tmp_path / "r" / "log.jsonl").read_text().splitlines()
             if json.loads(l)["kind"] == "train"]
    assert steps == [4, 6, 7]


def test_export_parity_and_metadata(trained):
    from track3d_train.edgetrack.export import parity

    for size in (256, 336):   # the normal and the wider 'lost' search
        p = parity(trained["net"], trained["pz"], trained["px"], instance_size=size)
        assert p["kernel_max_abs"] < 1e-4 and p["logit_max_abs"] < 1e-3
        assert p["ltrb_max_abs"] < 1e-4 * max(1.0, p["ltrb_scale"])
        assert p["logit_shape"] == [1, size // 16, size // 16]
    meta = OnnxModel(trained["px"], 1, "edgetrack-search").meta
    for k in ("exemplar_size", "instance_size", "lost_instance_size", "total_stride", "score", "tracking"):
        assert k in meta
    assert meta["exemplar_size"] == 128 and meta["total_stride"] == 16
    assert set(meta["tracking"]) >= {"window_influence", "penalty_k", "size_lr", "score_threshold", "context_amount"}
    assert meta["score"]["a"] > 0       # calibrated: a higher logit is a higher score
    assert OnnxModel(trained["pz"], 1, "edgetrack-template").meta["kind"] == "edgetrack-template"


JUMP_X = 190.0     # 90 px: past the tiny model's normal reach (~80 px), inside the wide one (~105)


def _exit_and_return_sequence():
    """A textured blob moving right, fully out of view for 8 frames, then coming back."""
    from track3d_train.siamfc.synthetic import blob_sprite, star_field

    rng = np.random.default_rng(3)
    h, w = 240, 320
    bg = star_field(h, w, rng)
    sprite, mask = blob_sprite(40, rng)
    ys, xs = np.nonzero(mask > 0.5)
    xs_path = list(np.linspace(100, 290, 20)) + [400.0] * 8 + list(np.linspace(290, 150, 15))
    frames, boxes, absent = [], [], []
    for i, x in enumerate(xs_path):
        y = 120 + 10 * np.sin(i / 5)
        m = np.array([[1.0, 0, x - 20], [0, 1.0, y - 20]])
        s = cv2.warpAffine(sprite, m, (w, h))
        k = cv2.warpAffine(mask, m, (w, h))[..., None]
        frames.append(np.clip(bg * (1 - k) + s * k + rng.normal(0, 2, (h, w, 3)), 0, 255).astype(np.uint8))
        boxes.append([x - 20 + xs.min(), y - 20 + ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()])
        absent.append(x - 20 >= w)
    return frames, np.array(boxes), np.array(absent)


# The runtime's follow / lost / re-acquire logic is tested with the shipped network: the tiny
# model of the `trained` fixture is too weak to follow this sequence with any margin, and how weak
# moves with the host's BLAS code path (on an Intel host with AVX-512 it lost the blob on the first
# frames, IoU 0.04; the same training with MKL held to its AVX2 path 0.56): a test of the training,
# not of the runtime. The shipped model holds it by a wide margin (IoU 0.85 before the exit, 0.82
# after the return).
def test_runtime_follows_reports_lost_and_recovers():
    from track3d.edgetrack import create
    from track3d.trackers2d import Tracker2D

    frames, gt, absent = _exit_and_return_sequence()
    tr = create()
    assert isinstance(tr, Tracker2D)
    tr.init(frames[0], gt[0])
    oks, ious, scores = [], [], []
    for i in range(1, len(frames)):
        ok, box = tr.update(frames[i])
        assert box.shape == (4,) and box.dtype == np.float64 and 0.0 <= tr.score <= 1.0
        oks.append(ok)
        scores.append(tr.score)
        ious.append(float(iou_2d(box[None], gt[i][None])[0]))
        assert set(tr.timings_ms) == {"crop", "net", "post"}
    oks, ious, ab = np.array(oks), np.array(ious), absent[1:]
    before, after = np.arange(len(ab)) < 19, np.arange(len(ab)) >= 27 + 3
    assert ious[before].mean() > 0.5, ious[before]                  # follows
    lost = ~oks
    assert lost[ab].mean() >= 0.75 and lost[~ab].mean() <= 0.2      # knows when it is gone
    assert np.mean(np.array(scores)[ab]) < np.mean(np.array(scores)[~ab])
    assert ious[after].mean() > 0.5, ious[after]                     # recovers after the return


def _fast_sequence(steps):
    """The textured blob crossing the frame, moving steps[i] pixels right into frame i + 1."""
    from track3d_train.siamfc.synthetic import blob_sprite, star_field

    rng = np.random.default_rng(5)
    h, w = 240, 640
    bg = star_field(h, w, rng)
    sprite, mask = blob_sprite(40, rng)
    ys, xs = np.nonzero(mask > 0.5)
    frames, boxes = [], []
    for i, x in enumerate(40.0 + np.concatenate([[0.0], np.cumsum(steps)])):
        y = 120.0
        m = np.array([[1.0, 0, x - 20], [0, 1.0, y - 20]])
        s = cv2.warpAffine(sprite, m, (w, h))
        k = cv2.warpAffine(mask, m, (w, h))[..., None]
        frames.append(np.clip(bg * (1 - k) + s * k + rng.normal(0, 2, (h, w, 3)), 0, 255).astype(np.uint8))
        boxes.append([x - 20 + xs.min(), y - 20 + ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()])
    return frames, np.array(boxes, np.float64)


def test_motion_prediction_moves_the_search_by_the_smoothed_motion(trained, monkeypatch):
    """Hand case of the prediction: the search crop is centred at the last centre plus `motion`
    times the smoothed motion (v <- 0.5 v + 0.5 d) shrunk by the dead zone (5% of the search
    side), and a state round trip keeps the motion."""
    import track3d.edgetrack as E

    frames, gt = _fast_sequence([30.0] * 6)
    tr = E.create(model=trained["root"] / "model" / "et", motion=1.0)
    centres = []
    real = E.crop_square
    monkeypatch.setattr(E, "crop_square", lambda img, c, *a: (centres.append(np.array(c, float)), real(img, c, *a))[1])
    tr.init(frames[0], gt[0])
    v = np.zeros(2)
    moved = 0
    for i in range(1, 6):
        start = tr.center.copy()
        dead = 0.05 * tr.instance_size * tr._z_sz() / tr.exemplar_size
        speed = np.hypot(*v)
        want = start + (v * (1.0 - dead / speed) if speed > dead else 0.0)
        ok, _ = tr.update(frames[i])
        assert ok
        np.testing.assert_allclose(centres[-1], want)                # searched where predicted
        moved += speed > dead
        v = 0.5 * v + 0.5 * (tr.center - start)
        np.testing.assert_allclose(tr.velocity, v)
    assert moved >= 3                          # 30 px per frame is motion, not jitter
    twin = E.create(model=trained["root"] / "model" / "et", motion=1.0)
    twin.set_state(tr.get_state())
    assert np.array_equal(twin.velocity, tr.velocity)
    state = tr.get_state()
    del state["velocity"]                                            # a state from before the motion
    twin.set_state(state)
    assert np.array_equal(twin.velocity, np.zeros(2))
    with pytest.raises(ValueError, match="motion"):
        E.create(model=trained["root"] / "model" / "et", motion=-1.0)


def test_motion_prediction_follows_a_body_faster_than_half_the_search_region(trained):
    """A body speeding up to 90 px per frame: beyond the reach of a search at the last centre (a
    failure before the prediction), within it once the search moves with the body."""
    from track3d.edgetrack import create

    frames, gt = _fast_sequence([20.0, 40.0, 60.0, 75.0, 90.0, 90.0, 90.0])
    mean_iou = {}
    for motion in (0.0, 1.0):
        tr = create(model=trained["root"] / "model" / "et", motion=motion)
        tr.init(frames[0], gt[0])
        ious = []
        for i in range(1, len(frames)):
            _, box = tr.update(frames[i])
            ious.append(float(iou_2d(box[None], gt[i][None])[0]))
        mean_iou[motion] = np.mean(ious[3:])     # at the fastest
    assert mean_iou[1.0] > 0.5 and mean_iou[0.0] < 0.3, mean_iou


def _sprite_path(path, seed):
    """A 40 px blob on a 640 x 240 star field at x = path[i] (None: out of view), y = 100:
    (frames uint8 (240, 640, 3), boxes [x, y, w, h] or None)."""
    from track3d_train.siamfc.synthetic import blob_sprite, star_field

    rng = np.random.default_rng(seed)
    h, w = 240, 640
    bg = star_field(h, w, rng)
    sprite, mask = blob_sprite(40, rng)
    ys, xs = np.nonzero(mask > 0.5)
    frames, boxes = [], []
    for x in path:
        img = bg.copy()
        if x is not None:
            m = np.array([[1.0, 0, x - 20], [0, 1.0, 100.0]])
            k = cv2.warpAffine(mask, m, (w, h))[..., None]
            img = bg * (1 - k) + cv2.warpAffine(sprite, m, (w, h)) * k
            boxes.append([x - 20 + xs.min(), 100 + ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()])
        else:
            boxes.append(None)
        frames.append(np.clip(img + rng.normal(0, 2, (h, w, 3)), 0, 255).astype(np.uint8))
    return frames, boxes


def test_a_lost_search_sweeps_the_image_and_finds_a_body_that_moved_far(trained, monkeypatch):
    """Lost, the search stayed at the last centre: a body that came back far from it was never
    found again (a held-out sequence lost its last 22 frames that way). After SWEEP_AFTER lost
    frames every other search steps over a grid of the image."""
    import track3d.edgetrack as E

    path = [80.0] * 3 + [None] * 3 + [560.0] * 30           # gone, then back 480 px away
    frames, boxes = _sprite_path(path, seed=7)

    def first_found(sweep_after):
        monkeypatch.setattr(E, "SWEEP_AFTER", sweep_after)
        tr = E.create(model=trained["root"] / "model" / "et")
        tr.init(frames[0], np.array(boxes[0], float))
        for i in range(1, len(frames)):
            ok, box = tr.update(frames[i])
            if i >= 6 and ok and iou_2d(box[None], np.array(boxes[i], float)[None])[0] > 0.5:
                return i                                   # found after the return
        return None

    assert first_found(10 ** 6) is None                  # the search never left the last centre
    assert first_found(3) is not None


def test_the_frame_after_a_reacquisition_searches_the_wide_region(trained, monkeypatch):
    """A re-acquisition's jump is not motion, so the frame after it has no prediction: a body that
    came back and crossed the normal search region in one frame was lost again there (a held-out
    sequence forked that way between arithmetic variants). That frame now searches the wide lost
    region; the old behaviour is reproduced by clearing `settling` after every update.

    The tiny model is trained in the test, and its weights differ between CPUs (torch's kernels):
    on one host it re-acquired the jumped body at 0.76 IoU, on another its score there (0.33)
    fell just under its own calibrated threshold. So the test checks the search itself (the crop
    size of each frame) and that it sees the body the normal search misses (a higher score),
    not where one tiny model's threshold falls."""
    import track3d.edgetrack as E

    path = [100.0] * 3 + [None] * 2 + [100.0, JUMP_X, JUMP_X + 20, JUMP_X + 40]
    frames, boxes = _sprite_path(path, seed=11)
    sizes = []
    real_crop = E.crop_square
    monkeypatch.setattr(E, "crop_square", lambda img, c, side, size, colour: sizes.append(size)
                        or real_crop(img, c, side, size, colour))

    def run(settle):
        tr = E.create(model=trained["root"] / "model" / "et")
        tr.init(frames[0], np.array(boxes[0], float))
        sizes.clear()
        scores, ious = [], []
        for i in range(1, len(frames)):
            ok, box = tr.update(frames[i])
            if i == 5:
                assert ok and tr.settling                  # re-acquired where it left
            if not settle:
                tr.settling = False
            scores.append(tr.score)
            ious.append(float(iou_2d(box[None], np.array(boxes[i], float)[None])[0]) if ok and boxes[i] else 0.0)
        return tr, list(sizes), scores, ious

    tr, sizes_settle, score_settle, iou_settle = run(True)
    _, sizes_old, score_old, iou_old = run(False)
    wide, normal = tr.lost_instance_size, tr.instance_size
    assert wide > normal
    # frames 1-3 searched as tracked (normal; 3 is where the body is first missing), 4 lost (wide),
    # 5 re-acquires (wide); then frame 6, the one after the re-acquisition:
    assert sizes_settle[:5] == [normal, normal, normal, wide, wide] == sizes_old[:5]
    assert sizes_settle[5] == wide and sizes_old[5] == normal
    assert np.mean(iou_old[5:]) < 0.2                      # the old search: lost at the jump, not found again
    # the wide search sees the body 90 px off (score 0.33 against the normal search's 0.18 on the Intel
    # AVX-512 host; on the AMD hosts it scored above the threshold and tracked on at 0.76 IoU)
    assert score_settle[5] > score_old[5] + 0.05
    assert np.mean(iou_settle[5:]) > 0.6 or score_settle[5] < tr.score_threshold


def test_a_lost_tracker_reacquires_only_at_the_reacquisition_threshold():
    """Hysteresis: lost below `score_threshold`, found again only at `reacquire_threshold` or
    above (default: the lost threshold). A tracker that can never reach it stays lost after the
    exit; the default one finds the target when it returns; bad values are refused."""
    from track3d.edgetrack import create

    frames, gt, absent = _exit_and_return_sequence()

    def run(**kw):
        tr = create(**kw)      # the shipped network (see the test above)
        tr.init(frames[0], gt[0])
        return [tr.update(f)[0] for f in frames[1:]], tr

    oks, tr = run()
    assert tr.reacquire_threshold == tr.score_threshold
    first_lost = oks.index(False)
    assert any(oks[first_lost:])                                   # found again after the exit
    never, _ = run(reacquire_threshold=1.0)                        # a calibrated score is < 1
    assert never[:first_lost] == oks[:first_lost] and not any(never[first_lost:])
    for bad in (0.0, 1.5):
        with pytest.raises(ValueError, match="reacquire_threshold"):
            create(reacquire_threshold=bad)


def test_registry_builds_edgetrack_and_says_when_no_model_is_shipped(trained, tmp_path, monkeypatch):
    from track3d import onnxmodel
    from track3d import trackers2d as T

    assert "edgetrack" in T.available_trackers()
    tr = T.create_tracker("edgetrack", model=trained["root"] / "model" / "et", window_influence=0.2)
    assert tr.window_influence == 0.2
    monkeypatch.setattr(onnxmodel, "MODELS_DIR", tmp_path)     # a package without the model
    with pytest.raises(T.TrackerUnavailable, match="EdgeTrack"):
        T.create_tracker("edgetrack")
    monkeypatch.undo()
    with pytest.raises(ValueError, match="unknown EdgeTrack options"):
        T.create_tracker("edgetrack", model=trained["root"] / "model" / "et", scale_num=3)


def test_runtime_checks_its_input(trained):
    from track3d.edgetrack import create

    tr = create(model=trained["root"] / "model" / "et")
    with pytest.raises(RuntimeError):
        tr.update(np.zeros((50, 50, 3), np.uint8))
    with pytest.raises(ValueError, match="box"):
        tr.init(np.zeros((50, 50, 3), np.uint8), [0, 0, 0, 5])
    with pytest.raises(ValueError, match="uint8"):
        tr.init(np.zeros((50, 50), np.uint8), [0, 0, 5, 5])
    with pytest.raises(ValueError, match="multiple of the stride"):
        create(model=trained["root"] / "model" / "et", instance_size=130)


def test_cli_errors_are_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "track3d_train.cli", "edgetrack", "train", "--cache",
                        str(tmp_path / "none"), "--out", str(tmp_path / "r")], capture_output=True, text=True)
    assert r.returncode == 2 and "no EdgeTrack cache" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("command", ["fit-threshold", "eval"])
def test_cli_a_missing_model_is_one_line(tmp_path, tiny_dataset, command):
    """A model prefix that names no file ended in a TrackerUnavailable traceback."""
    r = subprocess.run([sys.executable, "-m", "track3d_train.cli", "edgetrack", command, "--model",
                        str(tmp_path / "none"), "--data", str(tiny_dataset), "--split", "train"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "model" in r.stderr


def test_shipped_edgetrack_carries_its_metadata_and_tracks_the_tiny_split(tiny_dataset):
    from track3d.dataset import Dataset
    from track3d.evaluation import TrackerSpec, evaluate_2d
    from track3d.onnxmodel import MODELS_DIR

    if not (MODELS_DIR / "edgetrack_search.onnx").is_file():
        pytest.skip("no EdgeTrack model shipped")
    meta = OnnxModel(MODELS_DIR / "edgetrack_search.onnx", 1, "edgetrack-search").meta
    assert meta["exemplar_size"] == 128 and meta["total_stride"] == 16 and meta["training"]["steps"] > 0
    assert meta["pad"] == [255.0, 0.0, 255.0]      # trained with it: the runtime's crop must fill with it
    assert OnnxModel(MODELS_DIR / "edgetrack_template.onnx", 1, "edgetrack-template").meta["config"] == meta["config"]
    seqs = Dataset(tiny_dataset).sequences("test")
    r = evaluate_2d(tiny_dataset, "test", [TrackerSpec("edgetrack", "none")])["edgetrack"]
    assert r["sequences"] == len(seqs) and r["ao_2d"] > 0.3 and r["lost_reported"] >= 0, r


def test_cli_eval_and_time_run_on_an_exported_model(trained, tiny_dataset, tmp_path, capsys):
    from track3d_train.edgetrack.cli import main

    prefix = str(trained["root"] / "model" / "et")
    assert main(["eval", "--model", prefix, "--data", str(tiny_dataset), "--max-sequences", "1", "--quiet",
                 "--out", str(tmp_path / "e.json")]) == 0
    rows = json.loads((tmp_path / "e.json").read_text())["trackers"]
    assert rows["model et"]["sequences"] == 1 and 0.0 <= rows["model et"]["ao_2d"] <= 1.0
    assert main(["time", "--model", prefix, "--repeats", "5"]) == 0
    assert "edgetrack search 256" in capsys.readouterr().out


def test_cli_eval_without_a_model_evaluates_the_shipped_pair(tiny_dataset, tmp_path):
    """`eval` without --model ran no tracker and wrote a report of zero sequences."""
    from track3d.onnxmodel import MODELS_DIR
    from track3d_train.edgetrack.cli import main

    if not (MODELS_DIR / "edgetrack_search.onnx").is_file():
        pytest.skip("no EdgeTrack model shipped")
    assert main(["eval", "--data", str(tiny_dataset), "--max-sequences", "1", "--quiet",
                 "--out", str(tmp_path / "e.json")]) == 0
    report = json.loads((tmp_path / "e.json").read_text())
    assert report["sequences"] == 1 and list(report["trackers"]) == ["edgetrack"]
    assert 0.0 <= report["trackers"]["edgetrack"]["ao_2d"] <= 1.0


def test_cli_eval_prints_a_table_and_json_on_asking(tiny_dataset, tmp_path, capsys):
    """`edgetrack eval` had printed ~20 lines of JSON per tracker: a table now, one row a tracker
    (the numbers of its --out file), and the JSON with --json."""
    from track3d.onnxmodel import MODELS_DIR
    from track3d_train.edgetrack.cli import main

    if not (MODELS_DIR / "edgetrack_search.onnx").is_file():
        pytest.skip("no EdgeTrack model shipped")
    args = ["eval", "--data", str(tiny_dataset), "--max-sequences", "1", "--quiet", "--compare", "mosse"]
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "e.json")]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    rows = json.loads((tmp_path / "e.json").read_text())["trackers"]
    assert lines[0].split()[:3] == ["name", "AO_2d", "ACE_2d(px)"] and len(lines) == 3
    for line, name in zip(lines[1:], ("edgetrack", "mosse")):
        assert line.split()[0] == name and float(line.split()[1]) == pytest.approx(rows[name]["ao_2d"], abs=6e-4)
    assert main([*args, "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)) == {"edgetrack", "mosse"}


def test_an_exported_pair_comes_back_to_torch_exactly_and_fine_tunes(trained, tmp_path, capsys):
    """`--init-from` an exported pair (a prefix, either file, a shipped name): the export folded
    every BatchNorm into its convolution; converted back, the net's outputs equal the graphs'
    and, calibrated on crops, its training mode starts near the same function; a fine-tune runs
    from it."""
    import torch

    from track3d_train.edgetrack.export import parity
    from track3d_train.edgetrack.from_onnx import is_exported_pair, model_from_onnx
    from track3d_train.edgetrack.train import train

    prefix = trained["root"] / "model" / "et"
    assert is_exported_pair(prefix) and is_exported_pair(trained["px"]) and is_exported_pair(trained["pz"])
    assert not is_exported_pair(trained["root"] / "run" / "ckpt.pt")
    net, ck = model_from_onnx(trained["pz"])
    p = parity(net, trained["pz"], trained["px"])
    assert p["kernel_max_abs"] < 1e-5 and p["logit_max_abs"] < 1e-4, p
    assert p["ltrb_max_abs"] < 1e-4 * max(1.0, p["ltrb_scale"]), p
    assert ck["config"]["widths"] == list(TINY["widths"])

    g = torch.Generator().manual_seed(1)
    z = net.normalise(torch.randint(0, 256, (8, 128, 128, 3), dtype=torch.uint8, generator=g))
    x = net.normalise(torch.randint(0, 256, (8, 256, 256, 3), dtype=torch.uint8, generator=g))
    cal, _ = model_from_onnx(prefix, calibration=(z.numpy(), x.numpy()))
    with torch.no_grad():
        ref = net(z, x)[0]
        assert float((cal(z, x)[0] - ref).abs().max()) < 1e-4       # eval mode: exact either way
        gaps = [float((m.train()(z, x)[0] - ref).abs().max()) for m in (net, cal)]
    assert gaps[1] < 0.5 * gaps[0], gaps                               # training mode: near it when calibrated

    summary = train(EdgeTrackConfig(**TINY), trained["root"] / "cache", tmp_path / "ft", steps=2, batch=4,
                    init_from=str(prefix), val_every=1000, progress=False)
    assert summary["step"] == 2 and f"initialised from {prefix}" in capsys.readouterr().out
    from track3d.onnxmodel import OnnxModel
    from track3d_train.cli import main as train_main

    assert train_main(["edgetrack", "export", "--checkpoint", str(tmp_path / "ft" / "ckpt.pt"),
                       "--out", str(tmp_path / "m" / "ft")]) == 0
    meta = OnnxModel(tmp_path / "m" / "ft_search.onnx", 1, "edgetrack-search").meta
    assert meta["training"]["fine_tuned_from"]["name"] == "et" and meta["training"]["steps"] == 2


def test_shipped_edgetrack_comes_back_to_torch_by_name():
    from track3d.onnxmodel import MODELS_DIR
    from track3d_train.edgetrack.export import parity
    from track3d_train.edgetrack.from_onnx import is_exported_pair, model_from_onnx

    if not (MODELS_DIR / "edgetrack_search.onnx").is_file():
        pytest.skip("no EdgeTrack model shipped")
    assert is_exported_pair("edgetrack")
    net, _ = model_from_onnx("edgetrack")
    p = parity(net, MODELS_DIR / "edgetrack_template.onnx", MODELS_DIR / "edgetrack_search.onnx")
    assert p["logit_max_abs"] < 1e-4 and p["ltrb_max_abs"] < 1e-4 * max(1.0, p["ltrb_scale"]), p
    with pytest.raises(ValueError, match="not an EdgeTrack search graph"):
        model_from_onnx(MODELS_DIR / "a3boxnet.onnx")


def test_cli_init_from_a_file_that_is_no_pair_is_one_line(trained, tmp_path):
    r = subprocess.run([sys.executable, "-m", "track3d_train.cli", "edgetrack", "train", "--cache",
                        str(trained["root"] / "cache"), "--out", str(tmp_path / "r"), "--init-from",
                        str(tmp_path / "none.onnx"), "--max-steps", "1"], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "none" in r.stderr


def test_cli_export_writes_a_new_prefix_and_refuses_a_shipped_one(trained, tmp_path, capsys, monkeypatch):
    """The command line of the export: a fresh prefix is written (parity printed); the shipped
    models' folder needs --force."""
    import track3d.onnxmodel
    from track3d_train.cli import main as train_main

    ck = str(trained["root"] / "run" / "ckpt.pt")
    assert train_main(["edgetrack", "export", "--checkpoint", ck, "--out", str(tmp_path / "m" / "et")]) == 0
    assert (tmp_path / "m" / "et_template.onnx").is_file() and "parity" in capsys.readouterr().out
    shipped = tmp_path / "shipped"          # a stand-in for track3d/models holding an EdgeTrack
    shipped.mkdir()
    for part in ("template", "search"):
        (shipped / f"edgetrack_{part}.onnx").write_bytes((tmp_path / "m" / f"et_{part}.onnx").read_bytes())
    monkeypatch.setattr(track3d.onnxmodel, "MODELS_DIR", shipped)
    before = (shipped / "edgetrack_search.onnx").stat().st_mtime_ns
    assert train_main(["edgetrack", "export", "--ckpt", ck, "--out", str(shipped / "edgetrack")]) == 2
    assert "is a shipped model" in capsys.readouterr().err
    assert (shipped / "edgetrack_search.onnx").stat().st_mtime_ns == before
    assert train_main(["edgetrack", "export", "--checkpoint", ck, "--out", str(shipped / "edgetrack"), "--force"]) == 0
    assert (shipped / "edgetrack_search.onnx").stat().st_mtime_ns != before


def test_export_records_the_training_data(trained, tmp_path, capsys):
    """The checkpoint carries its cache's identity into the exported metadata; a checkpoint from
    before that needs --cache, else a one-line error (a shipped model must say what made it)."""
    import json

    import onnx
    import torch

    from track3d_train.cli import main as train_main
    from track3d_train.siamfc.data import cache_data_info

    ck = trained["root"] / "run" / "ckpt.pt"
    want = cache_data_info(trained["root"] / "cache" / "target")["train_data_hash"]
    assert train_main(["edgetrack", "export", "--checkpoint", str(ck), "--out", str(tmp_path / "a" / "et")]) == 0
    meta = json.loads({p.key: p.value for p in onnx.load(str(tmp_path / "a" / "et_search.onnx")).metadata_props}["track3d"])
    assert meta["train_data_hash"] == want and meta["train_data"]
    assert "pad" not in meta                       # a mean-colour cache: the runtime's default
    old = {k: v for k, v in torch.load(str(ck), map_location="cpu", weights_only=False).items()
           if k not in ("train_data_hash", "train_data")}
    torch.save(old, str(tmp_path / "old.pt"))
    capsys.readouterr()
    assert train_main(["edgetrack", "export", "--checkpoint", str(tmp_path / "old.pt"), "--out", str(tmp_path / "b" / "et")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--cache" in err[0]
    assert train_main(["edgetrack", "export", "--checkpoint", str(tmp_path / "old.pt"), "--out", str(tmp_path / "b" / "et"),
                       "--cache", str(trained["root"] / "cache")]) == 0


def test_fit_threshold_runs_the_grid_picks_by_f1_and_writes_the_metadata(trained, tmp_path, capsys):
    """The lost threshold is fitted one pass per candidate on sequences with absent frames,
    written into both files' metadata (weights untouched), and the runtime then uses it."""
    import shutil

    from track3d.edgetrack import EdgeTracker
    from track3d.synthetic import make_synthetic_dataset
    from track3d_train.edgetrack.cli import main
    from track3d_train.edgetrack.threshold import fit_threshold

    data = make_synthetic_dataset(tmp_path / "ds", {"s0001": 10, "s0002": 8}, absent={"s0001": [4, 5, 6]},
                                  split="train")
    prefix = tmp_path / "m" / "et"
    prefix.parent.mkdir()
    for part in ("template", "search"):
        shutil.copy(trained["root"] / "model" / f"et_{part}.onnx", f"{prefix}_{part}.onnx")
    fit = fit_threshold(prefix, data, "train", [0.1, 0.9])
    assert [r["threshold"] for r in fit["rows"]] == [0.1, 0.9]
    assert all(r["absent_frames"] == 3 and 0.0 <= r["f1"] <= 1.0 for r in fit["rows"])
    best = max(fit["rows"], key=lambda r: (round(r["f1"], 6), r["ao_2d"]))
    assert fit["threshold"] == best["threshold"]
    import onnx

    def graphs():
        return [onnx.load(f"{prefix}_{p}.onnx").graph.SerializeToString() for p in ("template", "search")]

    graph_before = graphs()
    assert main(["fit-threshold", "--model", str(prefix), "--data", str(data), "--split", "train",
                 "--grid", "0.1,0.9", "--write", "--quiet"]) == 0
    assert "best:" in capsys.readouterr().out
    t = EdgeTracker(f"{prefix}_template.onnx", f"{prefix}_search.onnx")
    assert t.score_threshold == fit["threshold"]
    assert t.meta["score"]["threshold_fit"]["split"] == "train" and len(t.meta["score"]["threshold_fit"]["rows"]) == 2
    assert graphs() == graph_before
    # never on a test split; a grid outside (0, 1) is refused
    with pytest.raises(ValueError, match="not on a test split"):
        main(["fit-threshold", "--model", str(prefix), "--data", str(data), "--split", "test"])
    with pytest.raises(ValueError, match=r"lie in \(0, 1\)"):
        fit_threshold(prefix, data, "train", [0.0, 0.5])
    # the re-acquisition threshold: fitted after the lost threshold by the same F1, values below
    # it dropped, written into the metadata; the runtime takes it (old metadata: the threshold)
    from track3d_train.edgetrack.threshold import fit_reacquire
    assert t.reacquire_threshold == t.score_threshold
    rf = fit_reacquire(prefix, data, "train", [0.05, 0.5, 0.99], threshold=0.1)
    assert [r["reacquire_threshold"] for r in rf["rows"]] == [0.5, 0.99]
    best = max(rf["rows"], key=lambda r: (round(r["f1"], 6), round(r["ao_2d"], 6), -r["reacquire_threshold"]))
    assert rf["reacquire_threshold"] == best["reacquire_threshold"]
    assert main(["fit-threshold", "--model", str(prefix), "--data", str(data), "--split", "train",
                 "--grid", "0.1", "--reacquire-grid", "0.99", "--write", "--quiet"]) == 0
    t = EdgeTracker(f"{prefix}_template.onnx", f"{prefix}_search.onnx")
    assert (t.score_threshold, t.reacquire_threshold) == (0.1, 0.99)
    assert t.meta["score"]["threshold_fit"]["reacquire"]["rows"][0]["reacquire_threshold"] == 0.99
    assert graphs() == graph_before
    with pytest.raises(ValueError, match="re-acquisition thresholds"):
        fit_reacquire(prefix, data, "train", [0.05], threshold=0.1)



def test_a_huge_corrected_box_is_capped_not_a_crash():
    """correct([0, 0, 1, 1e200]) overflowed the crop size to 0: update() raised ZeroDivisionError
    (found by the fuzz test in the loop); the state box is capped at MAX_BOX_SCALE x the image,
    as SiamFC's."""
    from track3d.edgetrack import create
    from track3d.frames import MAX_BOX_SCALE

    t = create()
    image = np.zeros((120, 160, 3), np.uint8)
    t.init(image, [10.0, 10.0, 20.0, 20.0])
    t.correct([0.0, 0.0, 1.0, 1e200])
    ok, box = t.update(image)
    assert np.all(np.isfinite(box)) and box[3] <= MAX_BOX_SCALE * 160


@pytest.mark.parametrize("name", ["edgetrack", "siamfc-edge"])
def test_a_vanishing_box_is_raised_to_the_minimum_side_not_a_crash(name):
    """init with sides of 1.9e-182 x 1.4e-194 px underflowed the crop size (a product of the two
    sides) to 0 and update() raised ZeroDivisionError (found by the fuzz test in the loop); a
    learned tracker's state box is at least MIN_BOX_SIDE wide and tall, at init and in correct()."""
    from track3d import edgetrack, siamfc
    from track3d.frames import MIN_BOX_SIDE

    t = edgetrack.create() if name == "edgetrack" else siamfc.create("edge")
    image = np.random.default_rng(0).integers(0, 255, (120, 160, 3), dtype=np.uint8)
    t.init(image, [0.0, 0.0, 1.8916451195518112e-182, 1.3617089941179075e-194])
    assert np.all(t.target_sz >= MIN_BOX_SIDE)
    ok, box = t.update(image)
    assert np.all(np.isfinite(box)) and np.all(box[2:] > 0)
    t.correct([5.0, 5.0, 1e-300, 1e-300])
    ok, box = t.update(image)
    assert np.all(np.isfinite(box)) and np.all(box[2:] > 0)


def _sweep_cells_as_listed(side, ww, hh, k):
    """The sweep's cell as the first implementation listed them all (the reference)."""
    step = 0.8 * side
    xs = np.arange(side / 2.0, max(ww - side / 2.0, side / 2.0) + step, step)
    ys = np.arange(side / 2.0, max(hh - side / 2.0, side / 2.0) + step, step)
    cells = [(min(x, ww - side / 2.0) if ww > side else ww / 2.0, min(y, hh - side / 2.0) if hh > side else hh / 2.0)
             for y in ys for x in xs]
    return np.array(cells[(k // 2 - 1) % len(cells)], dtype=np.float64)


def test_the_sweep_of_a_sub_pixel_target_is_bounded_and_normal_ones_unchanged():
    """A lost target of a 0.1 px box listed every cell of a grid 0.08 px apart (0.6 s a frame;
    smaller, all the memory: a latency walkthrough). The cell is now found by its index and cells
    are at least SWEEP_MIN_STEP apart; for a search side of 10 px and more, the same cells."""
    from track3d import edgetrack as E

    t = E.create(threads=1)
    t.center = np.array([100.0, 100.0])
    for side, ww, hh in ((120.0, 640, 480), (37.5, 640, 480), (10.0, 320, 240), (700.0, 640, 480)):
        for lost in range(E.SWEEP_AFTER + 2, E.SWEEP_AFTER + 160, 2):   # even k: a sweep frame
            t.lost_frames = lost
            np.testing.assert_array_equal(t._lost_search_centre(side, ww, hh),
                                          _sweep_cells_as_listed(side, ww, hh, lost - E.SWEEP_AFTER))
    t.lost_frames = E.SWEEP_AFTER + 6     # before: a list of 2e15 cells (MemoryError)
    c = t._lost_search_centre(1e-4, 4000, 3000)
    assert 0 <= c[0] <= 4000 and 0 <= c[1] <= 3000
