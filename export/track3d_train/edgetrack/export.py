"""ONNX export of EdgeTrack as the two graphs the runtime (track3d.edgetrack) drives.

    <prefix>_template.onnx  template uint8 (1, 128, 128, 3) RGB -> kernel (1, 64, C)
    <prefix>_search.onnx    search uint8 (1, H, W, 3) RGB (H, W multiples of 16), kernel (1, 64, C)
                            -> logit (1, H/16, W/16), ltrb (1, 4, H/16, W/16) in search-crop pixels

Both files carry the same metadata (key 'track3d'): kind 'edgetrack-template' /
'edgetrack-search', sizes, stride, the cell-centre rule, the score calibration and every
tracking hyper-parameter, so the runtime needs nothing else, and one export id (`export_id`,
the sha256 of the two graphs as exported): the runtime refuses a pair whose ids differ.
"""
from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

from ..onnx_meta import EXPORT_ID, AtomicFiles, attach_metadata, export_id, require_parity
from .model import EdgeTrack

__all__ = ["TemplateGraph", "SearchGraph", "export_onnx", "parity", "model_metadata", "count_macs", "time_search"]

META_VERSION = 1


class TemplateGraph(nn.Module):
    def __init__(self, net: EdgeTrack):
        super().__init__()
        self.net = net

    def forward(self, template):
        return self.net.template(self.net.normalise(template))


class SearchGraph(nn.Module):
    def __init__(self, net: EdgeTrack):
        super().__init__()
        self.net = net

    def forward(self, search, kernel):
        logit, ltrb = self.net.track(kernel, self.net.normalise(search))
        return logit[:, 0], ltrb


def count_macs(net: EdgeTrack, size: int) -> int:
    """Multiply-accumulates of the backbone on a (size x size) crop plus, for the search size,
    the correlation and head (convolutions and the MatMul; BN folded, activations free)."""
    macs = 0

    def hook(m, i, o):
        nonlocal macs
        if isinstance(m, nn.Conv2d):
            macs += o.numel() // o.shape[0] * (m.in_channels // m.groups) * m.kernel_size[0] * m.kernel_size[1]

    hs = [m.register_forward_hook(hook) for m in net.modules() if isinstance(m, nn.Conv2d)]
    with torch.no_grad():
        net.eval()
        if size == net.cfg.exemplar_size:
            net.template(torch.zeros(1, 3, size, size))
        else:
            k = net.template(torch.zeros(1, 3, net.cfg.exemplar_size, net.cfg.exemplar_size))
            macs = 0
            net.track(k, torch.zeros(1, 3, size, size))
            n = size // net.cfg.total_stride
            macs += k.shape[1] * k.shape[2] * n * n
    for h in hs:
        h.remove()
    return int(macs)


def model_metadata(net: EdgeTrack, kind: str, extra: dict | None = None) -> dict:
    cfg = net.cfg
    meta = {
        "kind": kind, "version": META_VERSION, "model": "edgetrack",
        "exemplar_size": cfg.exemplar_size, "instance_size": cfg.instance_size,
        "lost_instance_size": cfg.lost_instance_size, "total_stride": cfg.total_stride,
        "cell_centre": "stride * i + stride / 2 (continuous crop coordinates)",
        "outputs": {"logit": "target logit per cell", "ltrb": "box edges' distances from the cell centre, crop pixels"},
        "input": {"dtype": "uint8", "layout": "NHWC", "color": "RGB", "range": "0-255",
                  "normalise": "(x / 255 - mean) / std inside the graph", "mean": list(cfg.mean), "std": list(cfg.std)},
        "score": {"calibration": "score = sigmoid(a * logit + b), Platt-fitted on held-out pairs",
                  "a": cfg.calib_a, "b": cfg.calib_b, "threshold": cfg.score_threshold},
        "tracking": {"context_amount": cfg.context_amount, "window_influence": cfg.window_influence,
                     "penalty_k": cfg.penalty_k, "size_lr": cfg.size_lr, "score_threshold": cfg.score_threshold},
        "params": int(sum(p.numel() for p in net.parameters())),
        "macs": {"template": count_macs(net, cfg.exemplar_size), "search": count_macs(net, cfg.instance_size)},
        "config": cfg.to_dict(),
    }
    if extra:
        meta.update(extra)
    return meta


def export_onnx(net: EdgeTrack, prefix: str | Path, extra_meta: dict | None = None,
                opset: int = 17, check=None) -> tuple[Path, Path]:
    """Write <prefix>_template.onnx and <prefix>_search.onnx with metadata; returns the paths.
    `check(template_tmp, search_tmp)` (the parity check) runs on the written pair before it
    replaces the files there: a pair that fails it, or an export killed before it passed, never
    stands at the paths."""
    prefix = Path(prefix)
    prefix.parent.mkdir(parents=True, exist_ok=True)
    cfg = net.cfg
    net = net.eval().cpu()
    pz = prefix.parent / f"{prefix.name}_template.onnx"
    px = prefix.parent / f"{prefix.name}_search.onnx"
    z = torch.randint(0, 256, (1, cfg.exemplar_size, cfg.exemplar_size, 3), dtype=torch.uint8)
    x = torch.randint(0, 256, (1, cfg.instance_size, cfg.instance_size, 3), dtype=torch.uint8)
    # both written beside their paths with their metadata, then renamed (all or none: a kill while
    # exporting leaves the pair that was there whole)
    with AtomicFiles(pz, px) as (tz_path, tx_path), warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        tz = TemplateGraph(net)
        k = tz(z)
        torch.onnx.export(tz, (z,), str(tz_path), dynamo=False, opset_version=opset, input_names=["template"],
                          output_names=["kernel"])
        torch.onnx.export(SearchGraph(net), (x, k), str(tx_path), dynamo=False, opset_version=opset,
                          input_names=["search", "kernel"], output_names=["logit", "ltrb"],
                          dynamic_axes={"search": {1: "height", 2: "width"},
                                        "logit": {1: "rows", 2: "cols"}, "ltrb": {2: "rows", 3: "cols"}})
        # one id in both files: the runtime refuses a template of another export beside the search
        # graph (a kill between AtomicFiles' two renames leaves such a pair)
        pair = {EXPORT_ID: export_id([tz_path, tx_path])}
        attach_metadata(tz_path, {**model_metadata(net, "edgetrack-template", extra_meta), **pair})
        attach_metadata(tx_path, {**model_metadata(net, "edgetrack-search", extra_meta), **pair})
        if check is not None:
            check(tz_path, tx_path)
    return pz, px


def parity(net: EdgeTrack, pz, px, seed: int = 0, instance_size: int | None = None) -> dict:
    """Max abs difference torch vs onnxruntime for both graphs on random uint8 crops."""
    from track3d.onnxmodel import OnnxModel

    cfg = net.cfg
    g = torch.Generator().manual_seed(seed)
    n = instance_size or cfg.instance_size
    z = torch.randint(0, 256, (1, cfg.exemplar_size, cfg.exemplar_size, 3), dtype=torch.uint8, generator=g)
    x = torch.randint(0, 256, (1, n, n, 3), dtype=torch.uint8, generator=g)
    net = net.eval()
    with torch.no_grad():
        k = TemplateGraph(net)(z)
        lg, bx = SearchGraph(net)(x, k)
    kz = OnnxModel(pz, 1, "edgetrack-template").run({"template": z.numpy()})[0]
    lo, bo = OnnxModel(px, 1, "edgetrack-search").run({"search": x.numpy(), "kernel": kz})
    out = {"kernel_max_abs": float(np.abs(kz - k.numpy()).max()),
           "logit_max_abs": float(np.abs(lo - lg.numpy()).max()),
           "ltrb_max_abs": float(np.abs(bo - bx.numpy()).max()),
           "kernel_scale": float(np.abs(k.numpy()).max()), "logit_scale": float(np.abs(lg.numpy()).max()),
           "ltrb_scale": float(np.abs(bx.numpy()).max()), "logit_shape": list(lo.shape)}
    require_parity(out, ("kernel", "logit", "ltrb"), "EdgeTrack")
    return out


def time_search(px, kernel: np.ndarray, size: int, threads: int = 1, repeats: int = 50) -> float:
    """Median ms of one search-graph call on a (size x size) crop."""
    from track3d.onnxmodel import OnnxModel

    m = OnnxModel(px, threads)
    feeds = {"search": np.random.default_rng(0).integers(0, 256, (1, size, size, 3), dtype=np.uint8),
             "kernel": kernel}
    tt = []
    for _ in range(repeats + 5):
        t0 = time.perf_counter()
        m.run(feeds)
        tt.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(tt[5:]))
