"""SiamFC: model shapes, loss, training steps, export + parity, metadata, runtime tracking."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from track3d.boxes import iou_2d  # noqa: E402
from track3d.onnxmodel import OnnxModel, ModelError  # noqa: E402
from track3d_train.siamfc.export import export_onnx, parity  # noqa: E402
from track3d_train.siamfc.model import (SiamFC, balanced_bce, config_for, make_labels, xcorr,  # noqa: E402
                                        xcorr_matmul)
from track3d_train.siamfc.synthetic import synthetic_sequence  # noqa: E402


def _tiny_cfg(**kw):
    return config_for("edge", width=0.125, **kw)


# -- model --------------------------------------------------------------------------------------
def test_faithful_shapes_are_those_of_bertinetto():
    cfg = config_for("faithful")
    assert cfg.channels == (96, 256, 384, 384, 256)
    net = SiamFC(cfg).eval()
    with torch.no_grad():
        fz = net.backbone(torch.zeros(1, 3, 127, 127))
        fx = net.backbone(torch.zeros(1, 3, 255, 255))
        r = net(torch.zeros(2, 3, 127, 127), torch.zeros(2, 3, 255, 255))
    assert fz.shape == (1, 256, 6, 6)
    assert fx.shape == (1, 256, 22, 22)
    assert r.shape == (2, 1, 17, 17)


def test_xcorr_matmul_equals_conv_xcorr():
    g = torch.Generator().manual_seed(0)
    z = torch.randn(1, 8, 6, 6, generator=g)
    x = torch.randn(3, 8, 14, 14, generator=g)
    a = xcorr_matmul(z, x)
    b = xcorr(z.expand(3, -1, -1, -1), x)
    assert a.shape == (3, 1, 9, 9)
    assert torch.allclose(a, b, atol=1e-4)


def test_labels_and_loss_hand_case():
    labels, weights = make_labels(5, 1.0)
    # centre and its 4 neighbours are within 1 cell
    assert int(labels.sum()) == 5 and labels[2, 2] == 1 and labels[0, 0] == 0
    assert math.isclose(float(weights[labels > 0].sum()), 0.5, rel_tol=1e-6)
    assert math.isclose(float(weights[labels == 0].sum()), 0.5, rel_tol=1e-6)
    zero = torch.zeros(1, 1, 5, 5)
    assert math.isclose(float(balanced_bce(zero, 1.0)), math.log(2), rel_tol=1e-5)
    perfect = (labels * 2 - 1).view(1, 1, 5, 5) * 20
    assert float(balanced_bce(perfect, 1.0)) < 1e-6
    wrong = -perfect
    assert float(balanced_bce(wrong, 1.0)) > 10


def test_a_few_steps_reduce_the_loss_on_synthetic_pairs(tmp_path):
    from track3d_train.siamfc.data import CropCache, PairSampler, build_cache, synthetic_sequences

    build_cache(synthetic_sequences(4, frames=8, seed=1), tmp_path / "c", max_frames=32, progress=False)
    cfg = _tiny_cfg()
    torch.manual_seed(0)
    net = SiamFC(cfg).train()
    z, x = PairSampler(CropCache(tmp_path / "c"), 127, 159, seed=0).sample(8)
    zt, xt = net.normalise(torch.from_numpy(z)), net.normalise(torch.from_numpy(x))
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(15):
        loss = balanced_bce(net(zt, xt), cfg.r_pos / cfg.total_stride)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.7 * losses[0], losses


# -- export -------------------------------------------------------------------------------------
@pytest.mark.parametrize("variant", ["edge", "faithful"])
def test_export_parity_and_metadata(tmp_path, variant):
    torch.manual_seed(0)
    cfg = config_for(variant)
    net = SiamFC(cfg).eval()
    pz, px = export_onnx(net, tmp_path / f"siamfc_{variant}", {"training": {"steps": 0}})
    p = parity(net, pz, px, scales=3, instance_size=cfg.instance_size)
    assert p["exemplar_max_abs"] < 1e-4 * max(1.0, p["exemplar_scale"])
    assert p["response_max_abs"] < 1e-4 * max(1.0, p["response_scale"])
    assert p["response_vs_conv_xcorr_max_abs"] < 1e-4 * max(1.0, p["response_scale"])
    r = (cfg.instance_size - 127) // 8 + 1
    assert p["response_shape"] == [3, r, r]
    # any search size and number of scales: one graph
    m = OnnxModel(px, 1, "siamfc-search")
    fz = OnnxModel(pz, 1, "siamfc-exemplar").run({"exemplar": np.zeros((1, 127, 127, 3), np.uint8)})[0]
    assert fz.shape == (1, cfg.channels[-1], 6, 6)
    out = m.run({"search": np.zeros((1, 159, 159, 3), np.uint8), "exemplar_feature": fz})[0]
    assert out.shape == (1, 5, 5)
    # metadata round trip
    meta = m.meta
    assert meta["kind"] == "siamfc-search" and meta["variant"] == variant
    assert meta["exemplar_size"] == 127 and meta["instance_size"] == cfg.instance_size
    assert meta["total_stride"] == 8 and meta["feature_size"] == 6
    assert meta["tracking"]["scale_num"] == cfg.scale_num
    assert meta["channels"] == list(cfg.channels)
    assert meta["training"] == {"steps": 0}
    assert OnnxModel(pz, 1).meta["kind"] == "siamfc-exemplar"
    with pytest.raises(ModelError):
        OnnxModel(pz, 1, "siamfc-search")


# -- runtime ------------------------------------------------------------------------------------
def hand_built_net(width=0.25) -> SiamFC:
    """A deterministic 'bright / dark' template matcher in the SiamFC graph: channel 0 carries the
    local brightness above the normalisation mean, channel 1 the darkness below it; every later
    layer passes both through its centre tap. Good enough to follow a lit blob on a dark sky."""
    cfg = config_for("edge", width=width, scale_num=3, instance_size=255)
    net = SiamFC(cfg).eval()
    convs = [m for m in net.backbone.modules() if isinstance(m, torch.nn.Conv2d)]
    with torch.no_grad():
        for m in net.backbone.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.reset_parameters()
                m.reset_running_stats()
        for i, c in enumerate(convs):
            c.weight.zero_()
            c.bias.zero_()
            k = c.kernel_size[0]
            if i == 0:
                c.weight[0] = 1.0 / (k * k * 3)
                c.weight[1] = -1.0 / (k * k * 3)
            else:
                c.weight[0, 0, k // 2, k // 2] = 1.0
                c.weight[1, 1, k // 2, k // 2] = 1.0
    return net


@pytest.fixture(scope="module")
def hand_models(tmp_path_factory):
    d = tmp_path_factory.mktemp("hand")
    return export_onnx(hand_built_net(), d / "hand")


def _track(tracker, frames, boxes):
    tracker.init(frames[0], boxes[0])
    out = [boxes[0]]
    for f in frames[1:]:
        ok, b = tracker.update(f)
        assert ok and b.shape == (4,) and b.dtype == np.float64
        out.append(b)
    return iou_2d(np.array(out), boxes)


def test_runtime_tracker_follows_a_synthetic_moving_target(hand_models):
    from track3d.siamfc import create

    frames, boxes = synthetic_sequence(40, 240, 320, np.random.default_rng(3), size_range=(36, 44), speed=4.0)
    # the target really moves: a tracker that stays put loses it (so this test can fail)
    assert (iou_2d(np.repeat(boxes[:1], len(boxes), 0), boxes) > 0.5).mean() < 0.5
    pz, px = hand_models
    tr = create(exemplar_model=pz, search_model=px)
    ious = _track(tr, frames, boxes)
    assert (ious > 0.5).mean() >= 0.85, ious.round(2)
    # one scale, a smaller search region: still follows it
    tr1 = create(exemplar_model=pz, search_model=px, scale_num=1, instance_size=191)
    assert tr1.response_size == 9
    assert (_track(tr1, frames, boxes) > 0.5).mean() >= 0.85


def test_runtime_correct_sets_centre_and_size(hand_models):
    from track3d.siamfc import create

    frames, boxes = synthetic_sequence(3, 240, 320, np.random.default_rng(4))
    pz, px = hand_models
    tr = create(exemplar_model=pz, search_model=px)
    tr.init(frames[0], boxes[0])
    new = np.array([10.0, 20.0, 30.0, 40.0])
    tr.correct(new)
    assert np.allclose(tr.box, new)
    ok, b = tr.update(frames[1])
    assert ok and np.all(np.isfinite(b))
    with pytest.raises(ValueError):
        tr.correct([0, 0, -1, 5])
    with pytest.raises(ValueError):
        tr.update(np.zeros((10, 10), np.uint8))
    with pytest.raises(TypeError):
        create(exemplar_model=pz, search_model=px, no_such_option=1)


def test_runtime_target_leaving_the_image_does_not_crash(hand_models):
    from track3d.siamfc import create

    pz, px = hand_models
    tr = create(exemplar_model=pz, search_model=px)
    img = np.zeros((120, 160, 3), np.uint8)
    tr.init(img, [150, 110, 30, 30])  # mostly outside
    for _ in range(3):
        ok, b = tr.update(img)
        assert np.all(np.isfinite(b))
    tr.correct([0, 0, 400, 400])  # larger than the image (area-resize path)
    ok, b = tr.update(img)
    assert np.all(np.isfinite(b))


@pytest.mark.parametrize("variant", ["edge", "faithful"])
def test_shipped_model_follows_a_synthetic_target(variant):
    from track3d.siamfc import create

    tr = create(variant=variant)        # shipped: a missing model is a failure, not a skip
    frames, boxes = synthetic_sequence(30, 240, 320, np.random.default_rng(5), size_range=(36, 44), speed=3.0)
    assert (_track(tr, frames, boxes) > 0.5).mean() >= 0.8


def test_runtime_never_imports_torch(hand_models):
    pz, px = hand_models
    code = (
        "import sys, numpy as np\n"
        "import track3d, track3d.siamfc as s\n"
        f"t = s.create(exemplar_model=r'{pz}', search_model=r'{px}')\n"
        "t.init(np.zeros((100, 100, 3), np.uint8), [40, 40, 20, 20]); t.update(np.zeros((100, 100, 3), np.uint8))\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('torch', 'track3d_train', 'track3d_sim')]\n"
        "print(bad); sys.exit(1 if bad else 0)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


# -- the CLI on the tiny simulated dataset -----------------------------------------------------
def test_cli_prepare_train_export_eval_on_tiny_data(tiny_dataset, tmp_path, capsys):
    import json

    from track3d_train.cli import main

    cache, run, prefix = tmp_path / "cache", tmp_path / "run", tmp_path / "m" / "siamfc_edge"
    assert main(["siamfc", "prepare", "--data", str(tiny_dataset), "--out", str(cache), "--max-frames", "40",
                 "--quiet"]) == 0
    args = ["siamfc", "train", "--variant", "edge", "--width", "0.125", "--train-instance-size", "159",
            "--cache", str(cache), "--out", str(run), "--batch", "2", "--quiet"]
    assert main(args + ["--steps", "3"]) == 0
    assert (run / "ckpt.pt").is_file() and (run / "loss.png").is_file()
    assert main(args + ["--steps", "5"]) == 0  # resumes at step 3
    assert json.loads((run / "summary.json").read_text())["step"] == 5
    assert "resumed from" in capsys.readouterr().out
    assert main(["siamfc", "export", "--checkpoint", str(run / "ckpt.pt"), "--out", str(prefix),
                 "--int8", str(cache)]) == 0
    meta = OnnxModel(str(prefix) + "_search.onnx", 1, "siamfc-search").meta
    # the int8 twin where precision="int8" / "auto" look for it (it had been <prefix>_int8_search.onnx)
    from track3d.onnxmodel import variant_path
    twin = variant_path(str(prefix) + "_search.onnx", "int8")
    assert twin.is_file() and not Path(str(prefix) + "_int8_search.onnx").exists()
    assert OnnxModel(str(prefix) + "_search.onnx", 1, "siamfc-search", precision="int8").file == twin
    assert meta["training"]["steps"] == 5 and meta["width"] == 0.125
    # the last checkpoint (written after the loop) still names the data it was trained on
    index = json.loads((cache / "index.json").read_text())
    assert meta["train_data_hash"] == index["data_hash"] and meta["train_data_hash"]
    # a kill after logging a step but before its checkpoint: the resumed run logs that step once
    with open(run / "log.jsonl", "a") as f:
        f.write(json.dumps({"step": 6, "loss": 1.0, "lr": 0.01, "elapsed_s": 0.0}) + "\n")
    assert main(args + ["--steps", "6"]) == 0
    steps = [json.loads(l)["step"] for l in (run / "log.jsonl").read_text().splitlines()]
    assert steps == sorted(set(steps)) and steps[-1] == 6, steps
    capsys.readouterr()
    assert main(["siamfc", "eval", "--model", str(prefix), "--data", str(tiny_dataset), "--split", "test",
                 "--max-sequences", "1"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["sequences"] == 1 and 0.0 <= res["ao_2d"] <= 1.0 and "ao_3d" not in res


def test_models_are_parameters_and_count_their_own_time():
    """A tracker takes built model objects (benchmarks pass torch stand-ins or timed models
    this way); each model sums its run time, so nothing needs to wrap or replace run()."""
    from track3d.onnxmodel import models_of
    from track3d.siamfc import SiamFCTracker, model_paths

    try:
        z, x = (OnnxModel(p) for p in model_paths("edge"))
    except ModelError:
        pytest.skip("no shipped SiamFC-edge model")
    t = SiamFCTracker(z, x)
    assert t.exemplar is z and t.search is x and models_of(t) == {"exemplar": z, "search": x}
    img = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    assert z.run_ms == 0.0
    t.init(img, np.array([100.0, 80, 40, 30]))
    t.update(img)
    assert z.run_ms > 0.0 and x.run_ms > 0.0
    with pytest.raises(ModelError, match="siamfc-exemplar"):
        SiamFCTracker(x, z)
