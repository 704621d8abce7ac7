"""ONNX export of A3BoxNet with its metadata, and the torch / onnxruntime parity check.

The graph takes ``points`` (B, N, 3) float32 (centroid-subtracted) and, unless the model was
trained without it, ``category`` (B, C) one-hot; batch AND point count are dynamic axes
(max-pool makes the net valid for any N; the metadata's num_points is the N it was trained
with and that the runtime samples). Outputs: center1, center2, size_scores, size_residuals.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from track3d.boxes import SIZE_TEMPLATES
from track3d.dataset import COARSE_CATEGORIES
from track3d.boxnet import INPUT_CATEGORY, INPUT_POINTS, KIND, OUTPUTS
from track3d.size_coding import size_coding

from ..onnx_meta import AtomicFiles, attach_metadata
from .data import cache_past_views

__all__ = ["MODEL_VERSION", "OPSET", "export_onnx", "parity_check", "model_metadata"]

MODEL_VERSION = "1.0"
OPSET = 17
FAMILIES = list(COARSE_CATEGORIES)




def model_metadata(model, extra: dict | None = None) -> dict:
    cfg = model.config
    meta = {
        "kind": KIND, "version": MODEL_VERSION, "architecture": "A3BoxNet (Frustum PointNets v1 form, no seg/heading)",
        "num_points": int(cfg.num_points), "num_categories": int(cfg.num_categories),
        "use_category": bool(cfg.use_category), "categories": FAMILIES[:cfg.num_categories],
        "width": float(cfg.width), "size_templates": SIZE_TEMPLATES.tolist(), "size_norm": cfg.size_norm,
        "normalisation": size_coding(cfg.size_norm).description,
        "inputs": {INPUT_POINTS: "B x N x 3 float32 centred"} |
                  ({INPUT_CATEGORY: f"B x {cfg.num_categories} float32 one-hot"} if cfg.use_category else {}),
        "outputs": list(OUTPUTS), "opset": OPSET,
    }
    meta.update(extra or {})
    return meta


def export_onnx(model, path: str | Path, extra_meta: dict | None = None, opset: int = OPSET,
                check=None) -> Path:
    """Write the model with its metadata to `path`; `check(tmp)` (e.g. the parity check) runs on the
    written file before it replaces `path`: a file that fails it, or an export killed before it
    passed, never stands at `path` (it had been renamed into place first and checked after, so a
    kill in between left an unchecked model that the same command then refused to redo)."""
    import torch

    model.eval()
    cfg = model.config
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    pts = torch.randn(2, cfg.num_points, 3)
    args = (pts, torch.nn.functional.one_hot(torch.tensor([0, 1]), cfg.num_categories).float())
    names = [INPUT_POINTS, INPUT_CATEGORY]
    dyn = {INPUT_POINTS: {0: "batch", 1: "num_points"}, INPUT_CATEGORY: {0: "batch"}}
    if not cfg.use_category:
        args, names = (pts, None), [INPUT_POINTS]
        dyn.pop(INPUT_CATEGORY)
    for o in OUTPUTS:
        dyn[o] = {0: "batch"}
    import warnings

    # The TorchScript exporter (dynamo=False): the dynamo exporter needs onnxscript, which the
    # `train` extra does not install; this one is deprecated but exact for this graph.
    # Written beside `path` with its metadata, then renamed: a kill while exporting leaves the file
    # that was there whole (it had been written in place, then saved over to add the metadata).
    with AtomicFiles(path) as (tmp,), torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(model, args, str(tmp), input_names=names, output_names=list(OUTPUTS),
                          dynamic_axes=dyn, opset_version=opset, dynamo=False, do_constant_folding=True)
        attach_metadata(tmp, model_metadata(model, extra_meta))
        if check is not None:
            check(tmp)
    return path


def parity_check(model, path: str | Path, batches=(1, 3), num_points: int | None = None, seed: int = 0,
                 atol: float = 1e-4, rtol: float = 1e-4) -> dict:
    """Run torch and onnxruntime on the same random inputs; raise AssertionError beyond float32
    noise. Returns the largest absolute difference per output."""
    import torch

    from track3d.boxnet import A3BoxNetEstimator, one_hot

    est = A3BoxNetEstimator(path, threads=1)
    rng = np.random.default_rng(seed)
    n = num_points or model.config.num_points
    worst = {o: 0.0 for o in OUTPUTS}
    model.eval()
    for b in batches:
        pts = (rng.normal(size=(b, n, 3)) * rng.uniform(0.5, 20.0, size=(b, 1, 1))).astype(np.float32)
        cats = rng.integers(0, model.config.num_categories, size=b)
        with torch.no_grad():
            ref = [o.numpy() for o in model(torch.from_numpy(pts),
                                            torch.from_numpy(one_hot(cats, model.config.num_categories)))]
        got = est.infer(pts, cats)
        for name, r, g in zip(OUTPUTS, ref, got):
            if r.shape != g.shape:
                raise AssertionError(f"{name}: torch shape {r.shape} != onnxruntime shape {g.shape}")
            d = float(np.max(np.abs(r - g)))
            worst[name] = max(worst[name], d)
            if not np.allclose(r, g, atol=atol, rtol=rtol):
                raise AssertionError(f"{name}: torch and onnxruntime differ by {d:.3g} (atol {atol}, batch {b})")
    return worst


def _teacher_record(train_config: dict) -> dict | None:
    """{"file", "weight"} of the A3BoxNet these weights also learnt to imitate (--distill-from), or None."""
    teacher, weight = train_config.get("distill_from"), float(train_config.get("distill_weight") or 0.0)
    if not teacher or weight <= 0:
        return None
    return {"file": Path(str(teacher)).name, "weight": weight}


def export_checkpoint(ckpt: str | Path, out: str | Path, check: bool = True, log=print,
                      depth_sensor: str | None = None) -> dict:
    """The one command: checkpoint -> ONNX with metadata (+ parity). Returns the metadata.
    depth_sensor: the sensor the model is for (metadata ``depth_sensor``; None: every sensor)."""
    from .data import data_name
    from .train import load_checkpoint

    model, ck = load_checkpoint(ckpt)
    hist = ck.get("history", {})
    last = hist.get("epochs", [{}])[-1] if hist.get("epochs") else {}
    extra = {"train_data_hash": hist.get("data_hash"), "train_data": data_name(hist.get("cache") or {}),
             "trained": {"epochs": ck.get("epoch", -1) + 1, "steps": ck.get("step"), "seconds": hist.get("seconds"),
                         "items": hist.get("train_items"), "batch": ck["train_config"].get("batch"),
                         "jitter": (hist.get("cache") or {}).get("jitter"),
                         "augment": {k: ck["train_config"].get(k) for k in ("flip", "flip_y", "scale_aug", "stretch_aug")},
                         "fine_tuned_from": hist.get("init_from"),   # the run these weights started from
                         "distilled_from": _teacher_record(ck["train_config"]),
                         "val": last.get("val")},
             "exported": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    if depth_sensor:
        extra["depth_sensor"] = str(depth_sensor)
    past = cache_past_views(hist.get("cache") or {})
    if past:   # trained on frustums beside the body's past views: the runtime gives it them
        extra["past_views"] = past
    worst: dict = {}
    path = export_onnx(model, out, extra, check=(lambda tmp: worst.update(parity_check(model, tmp))) if check else None)
    meta = json.loads(json.dumps(model_metadata(model, extra)))
    if check:
        log("parity torch vs onnxruntime: max |diff| " + ", ".join(f"{k} {v:.2e}" for k, v in worst.items()))
        meta["parity"] = worst
    log(f"wrote {path} ({Path(path).stat().st_size / 1e6:.2f} MB)")
    return meta
