"""A3BoxNet: model, losses, data, training steps, export + parity, runtime decoding, estimator."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from track3d.boxes import SIZE_TEMPLATES
from track3d.boxnet import one_hot

torch = pytest.importorskip("torch")

from track3d_train.boxnet.losses import boxnet_loss, huber_norm  # noqa: E402
from track3d_train.boxnet.model import A3BoxNet, BoxNetConfig  # noqa: E402


def test_loss_with_per_axis_scale():
    z3 = torch.zeros(1, 3)
    res_label = torch.tensor([[0.1, 0.0, 0.5]])
    _, terms = boxnet_loss((z3, z3, torch.zeros(1, 14), torch.zeros(1, 14, 3)), z3, torch.tensor([0]),
                           res_label, torch.tensor([[2.0, 1.0, 0.8]]))
    assert terms["size_res"] == pytest.approx(0.5 * (0.2 ** 2 + 0.4 ** 2))   # |(0.2, 0, 0.4)| m < 1


def test_one_hot():
    np.testing.assert_array_equal(one_hot([0, 2, -1], 3), [[1, 0, 0], [0, 0, 1], [0, 0, 0]])
    assert one_hot(1, 3).shape == (3,)
    with pytest.raises(ValueError):
        one_hot(3, 3)


# --- model and losses ----------------------------------------------------------------------

@pytest.mark.parametrize("use_category", [True, False])
def test_model_shapes(use_category):
    m = A3BoxNet(BoxNetConfig(num_points=64, width=0.25, use_category=use_category))
    out = m(torch.randn(4, 64, 3), torch.eye(3)[[0, 1, 2, 0]])
    assert [tuple(o.shape) for o in out] == [(4, 3), (4, 3), (4, 14), (4, 14, 3)]
    m.eval()
    out = m(torch.randn(1, 100, 3), torch.eye(3)[[1]])   # any N, batch of 1 in eval mode
    assert tuple(out[3].shape) == (1, 14, 3)


def test_paper_widths():
    m = A3BoxNet(BoxNetConfig(width=1.0))
    convs = [l.out_channels for l in m.center_net.mlp if isinstance(l, torch.nn.Conv1d)]
    fcs = [l.out_features for l in m.center_net.fc if isinstance(l, torch.nn.Linear)]
    assert convs == [128, 128, 256] and fcs == [256, 128, 3]
    convs = [l.out_channels for l in m.box_net.mlp if isinstance(l, torch.nn.Conv1d)]
    fcs = [l.out_features for l in m.box_net.fc if isinstance(l, torch.nn.Linear)]
    assert convs == [128, 128, 256, 512] and fcs == [512, 256, 3 + 14 * 4]
    assert m.box_net.fc[0].in_features == 512 + 3       # global feature + one-hot category


def test_loss_hand_case():
    center1 = torch.zeros(1, 3)
    center2 = torch.zeros(1, 3)
    scores = torch.zeros(1, 14)                          # uniform: cross-entropy = ln 14
    residuals = torch.zeros(1, 14, 3)
    crel = torch.tensor([[3.0, 4.0, 0.0]])               # |.| = 5
    total, terms = boxnet_loss((center1, center2, scores, residuals), crel, torch.tensor([2]),
                               torch.tensor([[0.1, 0.0, 0.0]]), torch.tensor([2.0]))
    assert terms["center1"] == pytest.approx(5 - 0.5)            # Huber delta 1, linear branch
    assert terms["center2"] == pytest.approx(2 * (5 - 1))        # Huber delta 2, linear branch
    assert terms["size_cls"] == pytest.approx(math.log(14), rel=1e-6)
    assert terms["size_res"] == pytest.approx(0.5 * 0.2 ** 2)    # gamma = 0.1 * 2 m, quadratic branch
    assert float(total) == pytest.approx(4.5 + 8 + math.log(14) + 0.02, rel=1e-6)


def test_huber_gradient_at_zero_is_finite():
    v = torch.zeros(2, 3, requires_grad=True)
    huber_norm(v, 1.0).sum().backward()
    assert torch.all(torch.isfinite(v.grad)) and float(v.grad.abs().sum()) == 0.0


def test_iou_3d_hand_case_and_the_runtime_formula():
    from track3d.boxes import iou_3d as iou_np
    from track3d_train.boxnet.losses import iou_3d

    # two 2 m cubes, one shifted 1 m in x: overlap 1 x 2 x 2 = 4, union 8 + 8 - 4 = 12
    c = torch.tensor([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0], [0.0, 0.0, 10.0]])
    s = torch.full((3, 3), 2.0)
    c2 = c + torch.tensor([[1.0, 0, 0], [5.0, 0, 0], [0, 0, 0]])
    got = iou_3d(c, s, c2, s)
    assert got.tolist() == pytest.approx([1 / 3, 0.0, 1.0])
    rng = np.random.default_rng(1)
    a, b = rng.normal(0, 1, (50, 6)), rng.normal(0, 1, (50, 6))
    a[:, 3:], b[:, 3:] = np.abs(a[:, 3:]) + 0.5, np.abs(b[:, 3:]) + 0.5
    t = [torch.from_numpy(x) for x in (a[:, :3], a[:, 3:], b[:, :3], b[:, 3:])]
    np.testing.assert_allclose(iou_3d(*t).numpy(), iou_np(a, b), rtol=1e-12, atol=1e-15)


def test_decoded_sizes_are_the_runtime_decoding():
    from track3d.size_coding import size_coding
    from track3d_train.boxnet.losses import decoded_sizes

    rng = np.random.default_rng(2)
    cls = rng.integers(0, 14, 20)
    r = rng.normal(0, 0.3, (20, 3))
    for name, scale in [("extent", rng.uniform(0.5, 5, (20, 3))), ("frustum", rng.uniform(0.5, 5, (20, 3))),
                        ("points", rng.uniform(0.5, 5, 20))]:
        scores = np.full((20, 14), -5.0)
        scores[np.arange(20), cls] = 5.0
        res = np.zeros((20, 14, 3))
        res[np.arange(20), cls] = r
        want = size_coding(name).decode(np.zeros((20, 3)), scale, np.zeros((20, 3)), np.zeros((20, 3)), scores, res)
        got = decoded_sizes(torch.from_numpy(cls), torch.from_numpy(r), torch.from_numpy(scale))
        np.testing.assert_allclose(got.numpy(), want[:, 3:], rtol=1e-12)


def test_loss_iou_term_hand_case_and_off_by_default():
    center1, center2 = torch.zeros(1, 3), torch.zeros(1, 3)
    scores = torch.zeros(1, 14)
    scores[0, 0] = 1.0                                   # predicted class 0
    residuals = torch.zeros(1, 14, 3, requires_grad=True)
    scale = torch.tensor([[2.0, 2.0, 2.0]])              # "extent": size = E * (1 + r)
    crel = torch.tensor([[1.0, 0.0, 0.0]])               # the truth 1 m off in x, same 2 m cube (r = 0)
    args = ((center1, center2, scores, residuals), crel, torch.tensor([0]), torch.zeros(1, 3), scale)
    base, terms0 = boxnet_loss(*args)
    assert "iou" not in terms0
    total, terms = boxnet_loss(*args, iou_weight=3.0)
    assert terms["iou"] == pytest.approx(1 - 1 / 3)
    assert total.item() == pytest.approx(base.item() + 3.0 * (2 / 3), rel=1e-6)
    total.backward()                                     # the gradient reaches the predicted class's residual
    assert float(residuals.grad[0, 0].abs().sum()) > 0 and float(residuals.grad[0, 1:].abs().sum()) == 0


def test_the_train_curve_is_the_joint_loss_without_the_extra_terms():
    from track3d_train.boxnet.train import joint_loss_of

    terms = {"center1": 0.5, "center2": 0.25, "size_cls": 1.0, "size_res": 0.125, "iou": 0.3, "total": 2.475}
    assert joint_loss_of(terms) == 1.875                 # the four terms, not the IoU term in "total"
    assert joint_loss_of({"total": 3.0}) == 3.0          # an older record without its terms


def test_iou_weight_refuses_the_paper_coding(tiny_cache, tmp_path):
    from track3d_train.boxnet.train import TrainConfig, train

    cfg = TrainConfig(train_cache=str(tiny_cache[0]), out=str(tmp_path / "run"), num_points=64, width=0.25,
                      epochs=1, batch=8, size_norm="paper", iou_weight=1.0, max_steps=1)
    with pytest.raises(ValueError, match="not 'paper'"):
        train(cfg, progress=False, log=lambda *_: None)


def test_training_steps_reduce_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    m = A3BoxNet(BoxNetConfig(num_points=64, width=0.25))
    opt = torch.optim.Adam(m.parameters(), lr=3e-3)
    pts = torch.from_numpy(rng.normal(size=(16, 64, 3)).astype(np.float32))
    cat = torch.from_numpy(one_hot(rng.integers(0, 3, 16), 3))
    crel = torch.from_numpy(rng.normal(size=(16, 3)).astype(np.float32))
    cls = torch.from_numpy(rng.integers(0, 14, 16))
    res = torch.from_numpy(rng.normal(0, 0.1, (16, 3)).astype(np.float32))
    scale = torch.full((16,), 5.0)
    losses = []
    for _ in range(40):
        loss, _ = boxnet_loss(m(pts, cat), crel, cls, res, scale)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5])


# --- data, training, export on the tiny dataset -----------------------------------------------

@pytest.fixture(scope="module")
def tiny_cache(tiny_dataset, tmp_path_factory):
    from track3d_train.boxnet.data import prepare_split

    out = tmp_path_factory.mktemp("boxnet_cache")
    train = prepare_split(tiny_dataset, "train", out, jitters=2, max_points=512, min_points=8, progress=False)
    test = prepare_split(tiny_dataset, "test", out, jitters=0, max_points=512, min_points=8, progress=False)
    return train, test


def test_prepare_cache(tiny_cache, tiny_dataset):
    from track3d.dataset import Dataset
    from track3d.frustum import extract_frustum
    from track3d_train.boxnet.data import PointCache

    train = PointCache(tiny_cache[0])
    assert len(train) > 10 and train.info["split"] == "train" and len(train.info["data_hash"]) == 64
    assert set(np.unique(train.jittered)) <= {0, 1} and 0 in train.jittered and 1 in train.jittered
    assert np.all(train.n_full >= 8)
    # an oracle item is exactly the runtime frustum of its frame (before subsampling)
    i = int(np.nonzero(train.jittered == 0)[0][0])
    ds = Dataset(tiny_dataset)
    seq = ds.sequences("train")[int(train.seq[i])]
    fr = extract_frustum(seq.points(int(train.frame[i])), seq.gt2d[int(train.frame[i])], ds.camera.M)
    assert len(fr) == train.n_full[i]
    np.testing.assert_allclose(train.baseline[i], np.r_[(fr.min(0) + fr.max(0)) / 2, fr.max(0) - fr.min(0)],
                               atol=1e-5)
    test = PointCache(tiny_cache[1])
    assert np.all(test.jittered == 0) and len(test) > 0


def test_concat_caches_keeps_items_and_makes_sequences_unique(tiny_cache):
    from track3d_train.boxnet.data import PointCache

    a, b = PointCache(tiny_cache[0]), PointCache(tiny_cache[1])
    c = PointCache.concat([tiny_cache[0], tiny_cache[1]])
    assert len(c) == len(a) + len(b)
    np.testing.assert_array_equal(c.gt3d, np.concatenate([a.gt3d, b.gt3d]))
    # the second cache's sequence ids follow the first's: no two caches share a sequence id
    assert set(c.seq[: len(a)].tolist()).isdisjoint(c.seq[len(a):].tolist())
    assert len(set(c.seq.tolist())) == len(set(a.seq.tolist())) + len(set(b.seq.tolist()))
    # every item's points are the same array as in its source cache
    for src, off in ((a, 0), (b, len(a))):
        for i in (0, len(src) - 1):
            np.testing.assert_array_equal(c.points(off + i), src.points(i))
    assert c.info["data_hash"] not in (a.info["data_hash"], b.info["data_hash"])
    assert PointCache.concat([tiny_cache[0]]).info["data_hash"] == a.info["data_hash"]


def test_data_name_names_every_concatenated_dataset(tiny_cache, tmp_path):
    """A model fine-tuned on three caches recorded only the first dataset as its train_data."""
    from track3d_train.boxnet.data import PointCache, data_name

    a = PointCache(tiny_cache[0])
    assert data_name(a.info) == Path(a.info["root"]).name
    other = tmp_path / "other"
    other.mkdir()
    z = dict(np.load(tiny_cache[0], allow_pickle=False))
    info = json.loads(z["info"].tobytes().decode())
    info["root"] = str(tmp_path / "engine-train-sq")
    z["info"] = np.frombuffer(json.dumps(info).encode(), dtype=np.uint8)
    np.savez(other / "sq.npz", **z)
    c = PointCache.concat([tiny_cache[0], other / "sq.npz"])
    assert data_name(c.info) == Path(a.info["root"]).name + "+engine-train-sq"
    assert data_name({}) is None


def test_category_dropout_zeroes_some_vectors(tiny_cache):
    from track3d_train.boxnet.data import BoxNetSamples, PointCache

    cache = PointCache(tiny_cache[0])
    never = BoxNetSamples(cache, 64, cat_dropout=0.0)
    always = BoxNetSamples(cache, 64, cat_dropout=1.0)
    half = BoxNetSamples(cache, 64, cat_dropout=0.5)
    n = len(cache)
    assert all(never[i][1].sum() == 1.0 for i in range(n))
    assert all(always[i][1].sum() == 0.0 for i in range(n))
    zeros = sum(half[i][1].sum() == 0.0 for i in range(n))
    assert 0.2 * n < zeros < 0.8 * n
    # the points and labels do not depend on the dropout
    np.testing.assert_array_equal(never[3][0], always[3][0])


def test_augmentations_keep_points_inside_their_box(tiny_cache):
    """x / y mirroring and the scale about the camera centre move points and labels together:
    every point of an oracle frustum stays inside its (transformed) ground-truth box."""
    from track3d.boxes import decode_size
    from track3d_train.boxnet.data import BoxNetSamples, PointCache

    cache = PointCache(tiny_cache[0])
    cache = cache.subset(np.nonzero(cache.jittered == 0)[0])
    plain = BoxNetSamples(cache, 64)
    aug = BoxNetSamples(cache, 64, flip=True, flip_y=True, scale_sigma=0.2)
    signs, scales = set(), []
    for i in range(len(cache)):
        pts, _, crel, cls, res, scale = aug[i]
        size = decode_size(cls, res, scale)
        assert np.all(np.abs(pts - crel) <= size / 2 + 2e-3), i      # 1 mm depth quantisation
        p0, _, c0, k0, r0, s0 = plain[i]
        size0 = decode_size(k0, r0, s0)
        k = size.max() / size0.max()
        scales.append(k)
        assert 0.7 - 1e-6 <= k <= 1.4 + 1e-6
        np.testing.assert_allclose(size, size0 * k, rtol=1e-5)
        # the same sampled points, mirrored and scaled: p = p0 * (+-1, +-1, 1) * k
        m = np.sign(np.sum(pts * p0, axis=0))
        np.testing.assert_allclose(pts, p0 * m * k, rtol=1e-4, atol=1e-4)
        signs.add(float(m[1]))
    assert signs == {-1.0, 1.0}                                        # y is mirrored, sometimes
    assert np.std(scales) > 0.05                                       # the scale does vary


def test_stretch_moves_points_and_box_together(tiny_cache):
    """The per-axis stretch about the box centre: each axis of the points' offsets from the box
    centre and of the box size is multiplied by one factor in [0.4, 2.5]; the points stay inside
    their stretched box; the factors differ between axes and items."""
    from track3d.boxes import decode_size
    from track3d_train.boxnet.data import BoxNetSamples, PointCache

    cache = PointCache(tiny_cache[0])
    cache = cache.subset(np.nonzero(cache.jittered == 0)[0])
    plain = BoxNetSamples(cache, 64)
    aug = BoxNetSamples(cache, 64, stretch_sigma=0.4)
    ks = []
    for i in range(len(cache)):
        pts, _, crel, cls, res, scale = aug[i]
        size = decode_size(cls, res, scale)
        assert np.all(np.abs(pts - crel) <= size / 2 + 2e-3 * 2.5), i
        p0, _, c0, k0, r0, s0 = plain[i]
        size0 = decode_size(k0, r0, s0)
        k = size / size0
        assert np.all((0.4 - 1e-5 <= k) & (k <= 2.5 + 1e-5)), k
        # the same sampled points: offsets from the box centre scaled per axis by k
        np.testing.assert_allclose(pts - crel, (p0 - c0) * k, rtol=1e-4, atol=2e-4)
        ks.append(k)
    ks = np.array(ks)
    assert np.std(np.log(ks)) > 0.1 and np.mean(np.abs(ks[:, 0] - ks[:, 2])) > 0.05


def test_stretch_takes_one_sigma_or_three(tiny_cache):
    """One sigma is the same stream as three equal ones; (0, 0, s) stretches depth alone."""
    from track3d_train.boxnet.data import BoxNetSamples, PointCache

    cache = PointCache(tiny_cache[0])
    one, three = BoxNetSamples(cache, 64, stretch_sigma=0.4), BoxNetSamples(cache, 64, stretch_sigma=(0.4, 0.4, 0.4))
    z_only, plain = BoxNetSamples(cache, 64, stretch_sigma=(0.0, 0.0, 0.5)), BoxNetSamples(cache, 64)
    for i in range(min(len(cache), 6)):
        for a, b in zip(one[i], three[i]):
            np.testing.assert_array_equal(a, b)
        pz, p0 = z_only[i][0], plain[i][0]
        np.testing.assert_allclose(np.ptp(pz[:, :2], axis=0), np.ptp(p0[:, :2], axis=0), rtol=1e-5)


def test_frustum_bounds_follow_every_augmentation(tiny_cache):
    """The whole frustum's bounds are mirrored, scaled and stretched with the points: the
    item's x / y extents (from the bounds) still enclose its sample, and its reference is the
    bounds' middle."""
    from track3d_train.boxnet.data import BoxNetSamples, PointCache

    cache = PointCache(tiny_cache[0])
    aug = BoxNetSamples(cache, 64, size_norm="frustum", flip=True, flip_y=True, scale_sigma=0.1,
                        stretch_sigma=0.4)
    for i in range(len(cache)):
        pts, _, crel, cls, res, scale = aug[i]
        span = pts.max(axis=0) - pts.min(axis=0)
        assert np.all(scale[:2] >= span[:2] - 1e-4), i
        assert np.all(np.abs(pts[:, :2].max(axis=0) + pts[:, :2].min(axis=0)) <= scale[:2] - span[:2] + 1e-4), i
    assert len(cache) > 3


def test_init_from_starts_from_a_checkpoint_and_refuses_another_model(trained, tmp_path):
    import torch

    from track3d_train.boxnet.train import TrainConfig, train

    out, cfg, _ = trained
    src = torch.load(str(out / "best.pt"), map_location="cpu", weights_only=False)
    tune = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "tune"), "epochs": 1, "max_steps": 1, "lr": 1e-12,
                          "lr_min": 1e-12})
    h = train(tune, progress=False, log=lambda *_: None, init_from=str(out / "best.pt"))
    assert h["init_from"]["file"] == "best.pt"
    tuned = torch.load(str(tmp_path / "tune" / "last.pt"), map_location="cpu", weights_only=False)
    for k, v in src["model"].items():       # one step at lr 1e-12: the weights are the source's
        if v.dtype.is_floating_point and "running_" not in k:   # (batch-norm statistics move)
            torch.testing.assert_close(tuned["model"][k], v, rtol=1e-6, atol=1e-6)
    # another box coding of the same layers starts from the same weights (fine-tuning to it)
    recoded = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "recoded"), "epochs": 1, "max_steps": 1,
                             "size_norm": "frustum"})
    h = train(recoded, progress=False, log=lambda *_: None, init_from=str(out / "best.pt"))
    assert h["init_from"]["size_norm"] == cfg.size_norm
    other = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "other"), "width": 0.5, "max_steps": 1})
    with pytest.raises(ValueError, match="not an A3BoxNet checkpoint of this model"):
        train(other, progress=False, log=lambda *_: None, init_from=str(out / "best.pt"))


def test_jitter_box_stays_in_image():
    from track3d_train.boxnet.data import JitterSpec, jitter_box

    rng = np.random.default_rng(0)
    boxes = np.array([jitter_box([10, 20, 50, 40], rng, JitterSpec(), 160, 120) for _ in range(500)])
    assert np.all(boxes[:, 0] >= 0) and np.all(boxes[:, 0] + boxes[:, 2] <= 160 + 1e-9)
    centre_shift = boxes[:, 0] + boxes[:, 2] / 2 - 35
    assert 2 < np.std(centre_shift) < 15                 # ~0.1 w = 5 px, plus the 3x "slips"


@pytest.fixture(scope="module")
def trained(tiny_cache, tmp_path_factory):
    from track3d_train.boxnet.train import TrainConfig, train

    out = tmp_path_factory.mktemp("boxnet_run")
    cfg = TrainConfig(train_cache=str(tiny_cache[0]), out=str(out), num_points=128, width=0.25, epochs=2,
                      batch=8, val_every=2, lr=3e-3)
    hist = train(cfg, progress=False, log=lambda *_: None)
    return out, cfg, hist


def test_train_writes_checkpoints_and_resumes(trained):
    from track3d_train.boxnet.train import TrainConfig, train

    out, cfg, hist = trained
    assert len(hist["epochs"]) == 2 and (out / "last.pt").is_file() and (out / "best.pt").is_file()
    assert (out / "loss_curve.png").stat().st_size > 1000 and (out / "history.json").is_file()
    assert all(np.isfinite(e["train"]["total"]) for e in hist["epochs"])
    assert "AO_3d" in hist["epochs"][-1]["val"]
    # resuming a finished run does nothing more; a longer plan continues from the checkpoint
    more = TrainConfig(**{**cfg.__dict__, "epochs": 3})
    with pytest.raises(ValueError):
        train(TrainConfig(**{**cfg.__dict__, "width": 0.5}), progress=False, log=lambda *_: None)
    h3 = train(more, progress=False, log=lambda *_: None)
    assert len(h3["epochs"]) == 3 and h3["epochs"][0] == hist["epochs"][0]


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory):
    from track3d_train.boxnet.export import export_checkpoint

    path = tmp_path_factory.mktemp("boxnet_onnx") / "a3boxnet_test.onnx"
    meta = export_checkpoint(trained[0] / "last.pt", path, check=True, log=lambda *_: None)
    return path, meta


def test_export_parity_and_metadata(exported, trained):
    import onnx

    from track3d.onnxmodel import OnnxModel
    from track3d_train.boxnet.export import parity_check
    from track3d_train.boxnet.train import load_checkpoint

    path, meta = exported
    model = onnx.load(str(path))
    assert model.opset_import[0].version >= 17
    assert max(meta["parity"].values()) < 1e-4
    m = OnnxModel(path, kind="a3boxnet").meta
    assert m["num_points"] == 128 and m["num_categories"] == 3 and m["use_category"] is True
    assert np.allclose(m["size_templates"], SIZE_TEMPLATES) and m["size_norm"] == "points"
    assert len(m["train_data_hash"]) == 64 and m["version"] and "centroid" in m["normalisation"]
    assert m["categories"] == ["contact_binary", "spinning_top", "irregular"]
    # dynamic batch and point axes, explicitly: batch 5 with 300 points
    torch_model, _ = load_checkpoint(trained[0] / "last.pt")
    worst = parity_check(torch_model, path, batches=(5,), num_points=300, seed=3)
    assert max(worst.values()) < 1e-4


def test_an_exported_model_comes_back_into_torch_and_fine_tunes(exported, trained, tmp_path):
    """The shipped model has no checkpoint: its ONNX (BatchNorm folded into the convolutions)
    converts back, equal to the graph in eval mode; with calibration points a training-mode
    batch like them sees about the same function; train(init_from=X.onnx) starts from it."""
    from track3d_train.boxnet.export import parity_check
    from track3d_train.boxnet.from_onnx import model_from_onnx
    from track3d_train.boxnet.train import TrainConfig, load_checkpoint, train

    path, _ = exported
    src, _ = load_checkpoint(trained[0] / "last.pt")
    model, ck = model_from_onnx(path)
    assert max(parity_check(model, path, batches=(2,), num_points=200, seed=1).values()) < 1e-4
    assert ck["model_config"] == src.config.to_dict() and ck["imported_from"]["file"] == path.name
    rng = np.random.default_rng(0)
    pts = (rng.normal(size=(32, 128, 3)) * [2.0, 1.0, 0.5]).astype(np.float32)
    cat = torch.from_numpy(one_hot(np.zeros(32, int), 3))
    cal, _ = model_from_onnx(path, calibration=pts)
    assert max(parity_check(cal, path, batches=(2,), seed=1).values()) < 1e-4      # eval stays exact
    with torch.no_grad():
        ref = [o.numpy() for o in cal.eval()(torch.from_numpy(pts), cat)]
        # the per-point layers only: in training mode their output on the calibration batch
        # is the eval output (an identity BatchNorm without calibration would not be)
        feats = {}
        for name, m in (("cal", cal), ("plain", model)):
            m.train()
            feats[name] = m.center_net.mlp(torch.from_numpy(pts).transpose(1, 2)).numpy()
            m.eval()
        want = cal.center_net.mlp(torch.from_numpy(pts).transpose(1, 2)).numpy()
    assert np.allclose(feats["cal"], want, atol=1e-3)
    assert not np.allclose(feats["plain"], want, atol=1e-1)
    assert all(np.all(np.isfinite(r)) for r in ref)
    out, cfg, _ = trained
    tune = TrainConfig(**{**cfg.__dict__, "out": str(tmp_path / "tune"), "epochs": 1, "max_steps": 1})
    h = train(tune, progress=False, log=lambda *_: None, init_from=str(path))
    assert h["init_from"]["file"] == path.name
    with pytest.raises(ValueError, match="not an A3BoxNet model"):
        model_from_onnx(Path(__file__).resolve().parents[1] / "runtime/track3d/models/edgetrack_search.onnx")


def test_parity_detects_a_difference(exported, trained):
    from track3d_train.boxnet.export import parity_check
    from track3d_train.boxnet.train import load_checkpoint

    model, _ = load_checkpoint(trained[0] / "last.pt")
    with torch.no_grad():
        model.box_net.fc[-1].bias += 0.01
    with pytest.raises(AssertionError):
        parity_check(model, exported[0])


def test_export_without_category(tmp_path):
    from track3d.boxnet import A3BoxNetEstimator
    from track3d_train.boxnet.export import export_onnx, parity_check

    m = A3BoxNet(BoxNetConfig(num_points=64, width=0.25, use_category=False)).eval()
    path = export_onnx(m, tmp_path / "nocat.onnx")
    est = A3BoxNetEstimator(path)
    assert est.model.input_names == ["points"] and not est.use_category
    assert max(parity_check(m, path).values()) < 1e-4
    assert est.estimate(np.random.default_rng(0).normal(size=(50, 3)).astype(np.float32) + 10, 1).shape == (6,)


@pytest.mark.parametrize("size_norm", ["extent", "frustum"])
def test_per_axis_model_trains_exports_and_decodes(size_norm, tiny_cache, tmp_path):
    from track3d.boxnet import A3BoxNetEstimator
    from track3d.frames import point_bounds
    from track3d_train.boxnet.data import PointCache
    from track3d_train.boxnet.evaluate import onnx_runner, predict
    from track3d_train.boxnet.export import export_checkpoint
    from track3d_train.boxnet.train import TrainConfig, train

    cfg = TrainConfig(train_cache=str(tiny_cache[0]), out=str(tmp_path / "run"), num_points=64, width=0.25,
                      epochs=1, batch=8, val_every=2, size_norm=size_norm, max_steps=3, iou_weight=1.0)
    hist = train(cfg, progress=False, log=lambda *_: None)
    assert hist["config"]["iou_weight"] == 1.0          # the IoU term on: training still runs and decodes
    assert np.isfinite(hist["epochs"][-1]["val"]["AO_3d"])
    export_checkpoint(tmp_path / "run" / "last.pt", tmp_path / "ext.onnx", log=lambda *_: None)
    est = A3BoxNetEstimator(tmp_path / "ext.onnx")
    assert est.size_norm == size_norm and est.coding.name == size_norm
    pts = np.random.default_rng(0).uniform([-1, -2, 9], [1, 2, 10], size=(300, 3)).astype(np.float32)
    box = est.estimate(pts, 0)
    # a barely trained net: residuals ~0, so the size is about the points' extents (2, 4, 1)
    assert box.shape == (6,) and np.all(np.isfinite(box))
    np.testing.assert_allclose(box[3:], [2, 4, 1], rtol=0.5)
    # the loop's bounds give the answer the estimator computes without them
    np.testing.assert_array_equal(est.estimate(pts, 0, bounds=np.stack(point_bounds(pts))), box)
    # the batch evaluation path (bounds from the cache's whole-frustum box) gives the estimator's answer
    test = PointCache(tiny_cache[1])
    pred = predict(onnx_runner(est), test, est.num_points, seed=est.seed, size_norm=size_norm)
    b = test.baseline[0]     # the cache keeps <= 4096 of the frustum's points, and its whole box
    np.testing.assert_allclose(pred[0], est.estimate(test.points(0), int(test.category[0]),
                                                     bounds=np.stack([b[:3] - b[3:] / 2, b[:3] + b[3:] / 2])),
                               atol=1e-4)
    if size_norm == "frustum":
        # x / y follow the bounds: wider bounds, a wider box
        wide = np.stack(point_bounds(pts)).astype(np.float64) + [[-1, 0, 0], [1, 0, 0]]
        assert est.estimate(pts, 0, bounds=wide)[3] > box[3] + 1.0
        for bad, msg in [(wide[:, ::-1], "do not enclose"), (np.zeros(5), r"\(2, 3\)"),
                         (wide * [[1, 1, 1], [np.nan, 1, 1]], "finite"),
                         (wide + [[-100, 0, 0], [0, 0, 0]], "at most")]:
            with pytest.raises(ValueError, match=msg):
                est.estimate(pts, 0, bounds=bad)


def test_estimator_on_tiny_frustums(exported, tiny_cache):
    from track3d.boxnet import A3BoxNetEstimator, create
    from track3d_train.boxnet.data import PointCache
    from track3d_train.boxnet.evaluate import onnx_runner, oracle_metrics, predict

    est = create(model=exported[0], threads=2)
    test = PointCache(tiny_cache[1])
    box = est.estimate(test.points(0), int(test.category[0]))
    assert box.shape == (6,) and np.all(np.isfinite(box)) and np.all(box[3:] > 0)
    np.testing.assert_array_equal(box, est.estimate(test.points(0), int(test.category[0])))  # deterministic
    # the batch evaluation path gives the estimator's answer
    pred = predict(onnx_runner(est), test, est.num_points, seed=est.seed)
    np.testing.assert_allclose(pred[0], box, atol=1e-5)
    m = oracle_metrics(pred, test.gt3d, test.seq)
    assert 0 <= m["AO_3d"] <= 1 and 0 <= m["AO_bev"] <= 1 and m["frames"] == len(test)
    # degenerate inputs: one point, fewer points than N, unknown category; empty raises
    assert np.all(np.isfinite(est.estimate(np.array([[1.0, 2.0, 20.0]], np.float32), 0)))
    assert np.all(np.isfinite(est.estimate(test.points(0)[:5], -1)))
    with pytest.raises(ValueError):
        est.estimate(np.zeros((0, 3), np.float32), 0)
    with pytest.raises(ValueError):
        est.estimate(test.points(0), 7)
    assert isinstance(est, A3BoxNetEstimator)


def test_estimator_registry(exported):
    estimators = pytest.importorskip("track3d.estimators",
                                     reason="track3d.estimators (the loop's seam) is not in this checkout yet")
    est = estimators.create_estimator("a3boxnet", model=str(exported[0]))
    pts = np.random.default_rng(1).normal(size=(300, 3)).astype(np.float32) + [0, 0, 20]
    assert est.estimate(pts, 0).shape == (6,)


def test_runtime_never_imports_torch(exported):
    code = ("import sys, numpy as np\n"
            "from track3d.boxnet import A3BoxNetEstimator\n"
            f"est = A3BoxNetEstimator({str(exported[0])!r})\n"
            "est.estimate(np.random.default_rng(0).normal(size=(200, 3)).astype(np.float32) + [0, 0, 20], 0)\n"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('torch', 'track3d_train', 'track3d_sim')]\n"
            "assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("cmd", ["prepare", "train", "export", "eval"])
def test_cli_help(cmd, capsys):
    from track3d_train.cli import main

    with pytest.raises(SystemExit) as e:
        main(["boxnet", cmd, "--help"])
    assert e.value.code == 0
    assert "usage: track3d-train boxnet " + cmd in capsys.readouterr().out


def test_cli_eval(exported, tiny_cache, tmp_path):
    from track3d_train.boxnet.cli import main

    out = tmp_path / "eval.json"
    assert main(["eval", "--model", str(exported[0]), "--cache", str(tiny_cache[1]), "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert set(r) >= {"a3boxnet", "baseline"} and r["a3boxnet"]["frames"] == r["baseline"]["frames"]


@pytest.mark.parametrize("cmd", [["boxnet", "prepare", "--data", "{x}/none", "--out", "{x}/c.npz"],
                                 ["siamfc", "prepare", "--data", "{x}/none", "--out", "{x}/c"],
                                 ["boxnet", "export", "--ckpt", "{x}/none.pt", "--out", "{x}/m.onnx"]])
def test_cli_missing_inputs_are_one_line_errors(cmd, tmp_path, capsys):
    from track3d_train.cli import main

    assert main([c.format(x=tmp_path) for c in cmd]) == 2
    err = capsys.readouterr().err
    assert "error:" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_a_narrower_net_is_cut_from_a_wider_one_by_channel_importance(exported, trained, tmp_path):
    """Hand case: silence (BatchNorm scale and shift 0) every channel a half-width net lacks;
    the cut keeps exactly the others, so the narrow net computes the same function. Then a
    fine-tune at --width 0.5 starts from the shipped-style .onnx of a wider net."""
    from track3d_train.boxnet.narrow import narrow_checkpoint
    from track3d_train.boxnet.train import TrainConfig, train

    torch.manual_seed(0)
    cfg = BoxNetConfig(num_points=64, width=0.5, use_category=True)
    big = A3BoxNet(cfg).eval()
    small_cfg = BoxNetConfig(**{**cfg.to_dict(), "width": 0.25})
    small_shapes = {k: tuple(v.shape) for k, v in A3BoxNet(small_cfg).state_dict().items()}
    rng = np.random.default_rng(3)
    kept = {}
    with torch.no_grad():
        for m in big.modules():
            if isinstance(m, torch.nn.BatchNorm1d):
                m.weight.uniform_(0.5, 1.5)
                m.running_var.uniform_(0.5, 2.0)
        for name, branch in (("center", big.center_net), ("box", big.box_net)):
            bns = [m for m in list(branch.mlp) + list(branch.fc) if isinstance(m, torch.nn.BatchNorm1d)]
            for i, bn in enumerate(bns):
                n = bn.num_features
                keep = np.sort(rng.choice(n, max(8, round(n / 2)), replace=False))
                off = np.setdiff1d(np.arange(n), keep)
                bn.weight[off] = 0.0
                bn.bias[off] = 0.0
                kept[(name, i)] = keep
    src = {"model": big.state_dict(), "model_config": cfg.to_dict(), "epoch": 4}
    ck = narrow_checkpoint(src, 0.25)
    assert ck["model_config"]["width"] == 0.25 and ck["narrowed_from"] == {"width": 0.5} and ck["epoch"] == 4
    assert {k: tuple(v.shape) for k, v in ck["model"].items()} == small_shapes
    small = A3BoxNet(small_cfg)
    small.load_state_dict(ck["model"])
    small.eval()
    # the first box-net conv kept exactly the live channels, all three input columns
    w0 = big.box_net.mlp[0].weight.detach().numpy()
    assert np.array_equal(small.box_net.mlp[0].weight.detach().numpy(), w0[kept[("box", 0)]])
    pts = torch.from_numpy(rng.normal(size=(3, 64, 3)).astype(np.float32))
    cat = torch.from_numpy(one_hot(np.array([0, 1, 2]), 3))
    with torch.no_grad():
        for a, b in zip(big(pts, cat), small(pts, cat)):
            assert torch.allclose(a, b, atol=1e-5)
    with pytest.raises(ValueError, match="not narrower"):
        narrow_checkpoint(src, 0.5)
    # train(): a wider init is cut to the run's width (the fixture's net is width 0.25)
    path, _ = exported
    out, tcfg, _ = trained
    tune = TrainConfig(**{**tcfg.__dict__, "out": str(tmp_path / "narrow"), "width": 0.125, "epochs": 1,
                          "max_steps": 1})
    logs = []
    h = train(tune, progress=False, log=logs.append, init_from=str(path))
    assert h["init_from"]["file"] == path.name and any("narrowing" in str(m) for m in logs)


def test_distillation_loss_hand_case_and_a_run_with_a_teacher(exported, trained, tmp_path):
    """Zero when the student says what the teacher says; a 0.3 m shift of the stage-1 centre
    costs 0.5 x 0.3^2 twice (stage-1 and final centre, both in Huber's quadratic branch); a
    run with --distill-from logs the teacher term."""
    from track3d_train.boxnet.losses import distill_loss
    from track3d_train.boxnet.train import TrainConfig, train

    rng = np.random.default_rng(1)
    t = tuple(torch.from_numpy(rng.normal(size=s).astype(np.float32)) for s in ((4, 3), (4, 3), (4, 14), (4, 14, 3)))
    scale = torch.ones(4, 3)
    total, terms = distill_loss(t, t, scale)
    assert abs(float(total)) < 1e-6 and abs(terms["distill"]) < 1e-6
    shifted = (t[0] + torch.tensor([0.3, 0.0, 0.0]),) + t[1:]
    assert float(distill_loss(shifted, t, scale)[0]) == pytest.approx(2 * 0.5 * 0.09, abs=1e-5)
    other = t[:2] + (t[2] + torch.from_numpy(rng.normal(size=(4, 14)).astype(np.float32)), t[3])
    assert float(distill_loss(other, t, scale)[0]) > 0.01       # another size-class distribution
    path, _ = exported
    out, tcfg, _ = trained
    run = TrainConfig(**{**tcfg.__dict__, "out": str(tmp_path / "distill"), "epochs": 1, "max_steps": 2,
                         "distill_from": str(path), "distill_weight": 0.5})
    logs = []
    h = train(run, progress=False, log=logs.append, init_from=str(path))
    assert any("distilling from" in str(m) for m in logs)
    assert h["epochs"][-1]["train"]["distill"] > 0
    bad = TrainConfig(**{**run.__dict__, "out": str(tmp_path / "bad"), "size_norm": "extent"})
    with pytest.raises(ValueError, match="cannot teach"):
        train(bad, progress=False, log=lambda *_: None)


def test_a_past_views_model_trains_exports_and_takes_the_views(tiny_dataset, tmp_path):
    """--past-views: a frustum whose sequence has two registered views holds PAST_VIEWS' counts of
    points (the frustum's sample beside the views'), the cache records the counts, the exported
    model carries them, its estimator takes past= and its answer moves with the views; a model
    without them ignores past=. The cache needs every frame."""
    from track3d.boxnet import PAST_VIEWS, A3BoxNetEstimator, with_past_views
    from track3d_train.boxnet.data import PointCache, prepare_split
    from track3d_train.boxnet.export import export_checkpoint
    from track3d_train.boxnet.train import TrainConfig, train

    with pytest.raises(ValueError, match="every frame"):
        prepare_split(tiny_dataset, "train", tmp_path, jitters=0, past_views=True, frame_step=2, progress=False)
    path = prepare_split(tiny_dataset, "train", tmp_path, jitters=1, min_points=8, past_views=True, progress=False)
    cache = PointCache(path)
    assert cache.info["past_views"] == PAST_VIEWS
    sizes = {len(cache.points(i)) for i in range(len(cache))}
    joined = PAST_VIEWS["current"] + PAST_VIEWS["past"]
    assert any(PAST_VIEWS["current"] < n <= joined for n in sizes)   # frames with views ...
    assert any(n <= 4096 and cache.frame[i] == 0 for i, n in enumerate(map(len, map(cache.points, range(len(cache))))))
    cfg = TrainConfig(train_cache=str(path), out=str(tmp_path / "run"), num_points=64, width=0.25, epochs=1,
                      batch=8, val_every=2, size_norm="extent", use_category=False, max_steps=3)
    train(cfg, progress=False, log=lambda *_: None)
    meta = export_checkpoint(tmp_path / "run" / "last.pt", tmp_path / "pv.onnx", log=lambda *_: None)
    assert meta["past_views"] == PAST_VIEWS
    est = A3BoxNetEstimator(tmp_path / "pv.onnx")
    assert est.takes_past and est.past_views == PAST_VIEWS
    rng = np.random.default_rng(0)
    pts = rng.uniform([-1, -1, 9], [1, 1, 9.5], size=(300, 3)).astype(np.float32)
    past = rng.uniform([-1, -1, 9], [1, 1, 12], size=(700, 3)).astype(np.float32)
    alone = est.estimate(pts, -1)
    assert np.array_equal(est.estimate(pts, -1, past=None), alone)
    assert not np.array_equal(est.estimate(pts, -1, past=past), alone)
    # past_views=False: the same model on the frustum alone
    off = A3BoxNetEstimator(tmp_path / "pv.onnx", past_views=False)
    assert not off.takes_past and np.array_equal(off.estimate(pts, -1, past=past), alone)
    with pytest.raises(ValueError, match="past_views must be True or False"):
        A3BoxNetEstimator(tmp_path / "pv.onnx", past_views="no")
    # the joined cloud: the frustum sampled to "current", the views to at most "past"
    j = with_past_views(pts, past, 0)
    assert j.shape == (joined, 3) and j.dtype == np.float32
    assert len(with_past_views(pts, past[:10], 0)) == PAST_VIEWS["current"] + 10
    assert with_past_views(pts, None, 0) is not None and len(with_past_views(pts, None, 0)) == len(pts)
    with pytest.raises(ValueError):
        est.estimate(pts, -1, past=np.full((700, 3), np.nan, np.float32))   # checked on the sample it sees


def test_a_model_without_past_views_ignores_them(exported):
    from track3d.boxnet import A3BoxNetEstimator

    est = A3BoxNetEstimator(exported[0])
    assert not est.takes_past and est.past_views is None
    pts = np.random.default_rng(1).uniform([-1, -1, 9], [1, 1, 9.5], size=(300, 3)).astype(np.float32)
    assert np.array_equal(est.estimate(pts, 0, past=pts + [0, 0, 2]), est.estimate(pts, 0))


def _mixed_sensor_set(tmp_path):
    """A points-only tiny set of 3 train sequences whose sensors cycle ideal, ToF; and a copy of it
    holding only its ToF sequences (symlinked), as a set made of them alone would list them."""
    from track3d_sim.cli import main

    root = tmp_path / "mixed"
    assert main(["generate", "--preset", "tiny", "--seed", "4", "--train", "3", "--test", "0", "--frames", "4",
                 "--points-only", "--sensors", "ideal,tof", "--out", str(root), "--quiet"]) in (0, None)
    d = json.loads((root / "dataset.json").read_text())
    tof = [s for s in d["splits"]["train"]
           if json.loads((root / "train" / s / "meta.json").read_text())["depth_sensor"]["name"] == "tof"]
    only = tmp_path / "only-tof"
    (only / "train").mkdir(parents=True)
    for s in tof:
        (only / "train" / s).symlink_to(root / "train" / s)
    d["splits"] = {**{k: [] for k in d["splits"]}, "train": tof}
    (only / "dataset.json").write_text(json.dumps(d))
    return root, only, tof


def test_prepare_keeps_the_sequences_of_the_sensors_asked_for(tmp_path):
    """--sensors tof: a sensor's own model from a mixed set. The cache holds the ToF sequences
    only, cut exactly as a set holding only them is (the same jitter draws); no such sequence is
    a one-line error."""
    from track3d_train.boxnet.data import PointCache, prepare_split
    from track3d_train.cli import main as train_main

    root, only, tof = _mixed_sensor_set(tmp_path)
    assert 0 < len(tof) < 3
    a = PointCache(prepare_split(root, "train", tmp_path / "a.npz", jitters=2, min_points=4, progress=False,
                                 sensors=("ToF",)))
    b = PointCache(prepare_split(only, "train", tmp_path / "b.npz", jitters=2, min_points=4, progress=False))
    assert a.info["sequences"] == tof and a.info["sensors"] == ["tof"] and len(a) > 0
    with np.load(tmp_path / "a.npz") as fa, np.load(tmp_path / "b.npz") as fb:
        for k in ("points", "offsets", "gt3d", "box2d", "seq", "frame", "jittered"):
            np.testing.assert_array_equal(fa[k], fb[k])
    every = PointCache(prepare_split(root, "train", tmp_path / "c.npz", jitters=2, min_points=4, progress=False))
    assert len(every.info["sequences"]) == 3 and every.info["sensors"] is None
    with pytest.raises(ValueError, match="no sequence of split 'train'.*depth sensor flash-lidar"):
        prepare_split(root, "train", tmp_path / "d.npz", jitters=0, progress=False, sensors=("flash-lidar",))
    assert train_main(["boxnet", "prepare", "--data", str(root), "--sensors", "flash-lidar",
                       "--out", str(tmp_path / "e.npz"), "--quiet"]) != 0
    with pytest.raises(SystemExit):
        train_main(["boxnet", "prepare", "--data", str(root), "--sensors", "lidar", "--out", str(tmp_path / "f.npz")])
