"""ONNX export of SiamFC as two graphs the runtime (track3d.siamfc) drives, plus parity checks.

    <prefix>_exemplar.onnx   exemplar  uint8 (1, 127, 127, 3) RGB -> exemplar_feature (1, C, 6, 6)
    <prefix>_search.onnx     search    uint8 (S, H, W, 3) RGB (any S, any H = W >= 127),
                             exemplar_feature (1, C, 6, 6) -> response (S, R, R), R = (H-127)/8 + 1

Normalisation happens inside both graphs. Both files carry the same metadata (key 'track3d'):
kind 'siamfc-exemplar' / 'siamfc-search', sizes, stride, tracking hyper-parameters, and one export id
(`export_id`, the sha256 of the two graphs as exported): the runtime refuses a pair whose ids differ.
"""
from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn
from track3d.threads import check_threads

from ..onnx_meta import EXPORT_ID, AtomicFiles, attach_metadata, export_id, parent_fields, require_parity
from .model import SiamFC, SiamFCConfig, xcorr_matmul

__all__ = ["ExemplarGraph", "SearchGraph", "export_onnx", "parity", "model_metadata", "quantize_search"]

META_VERSION = 1


class ExemplarGraph(nn.Module):
    def __init__(self, net: SiamFC):
        super().__init__()
        self.net = net

    def forward(self, exemplar):
        return self.net.backbone(self.net.normalise(exemplar))


class SearchGraph(nn.Module):
    def __init__(self, net: SiamFC):
        super().__init__()
        self.net = net

    def forward(self, search, exemplar_feature):
        x = self.net.backbone(self.net.normalise(search))
        return xcorr_matmul(exemplar_feature, x)[:, 0] * self.net.cfg.out_scale


def model_metadata(cfg: SiamFCConfig, kind: str, extra: dict | None = None) -> dict:
    feat = (cfg.exemplar_size - 127) // cfg.total_stride + 6
    meta = {
        "kind": kind, "version": META_VERSION, "model": "siamfc", "variant": cfg.variant,
        "width": cfg.width, "channels": list(cfg.channels),
        "exemplar_size": cfg.exemplar_size, "instance_size": cfg.instance_size,
        "feature_size": feat, "total_stride": cfg.total_stride,
        "input": {"dtype": "uint8", "layout": "NHWC", "color": "RGB", "range": "0-255",
                  "normalise": "(x / 255 - mean) / std inside the graph",
                  "mean": list(cfg.mean), "std": list(cfg.std)},
        "tracking": {"context_amount": cfg.context_amount, "scale_num": cfg.scale_num,
                     "scale_step": cfg.scale_step, "scale_penalty": cfg.scale_penalty,
                     "scale_lr": cfg.scale_lr, "window_influence": cfg.window_influence,
                     "response_up": cfg.response_up},
        "config": cfg.to_dict(),
    }
    if extra:
        meta.update(extra)
    return meta


def export_onnx(net: SiamFC, prefix: str | Path, extra_meta: dict | None = None,
                opset: int = 17, check=None) -> tuple[Path, Path]:
    """Write <prefix>_exemplar.onnx and <prefix>_search.onnx with metadata; returns the paths.
    `check(exemplar_tmp, search_tmp)` (the parity check) runs on the written pair before it
    replaces the files there."""
    prefix = Path(prefix)
    prefix.parent.mkdir(parents=True, exist_ok=True)
    cfg = net.cfg
    net = net.eval().cpu()
    pz = prefix.parent / f"{prefix.name}_exemplar.onnx"
    px = prefix.parent / f"{prefix.name}_search.onnx"
    z = torch.randint(0, 256, (1, cfg.exemplar_size, cfg.exemplar_size, 3), dtype=torch.uint8)
    x = torch.randint(0, 256, (cfg.scale_num, cfg.instance_size, cfg.instance_size, 3), dtype=torch.uint8)
    # both written beside their paths with their metadata, then renamed (all or none: a kill while
    # exporting leaves the pair that was there whole)
    with AtomicFiles(pz, px) as (ez_path, ex_path), warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        ez = ExemplarGraph(net)
        feat = ez(z)
        torch.onnx.export(ez, (z,), str(ez_path), dynamo=False, opset_version=opset, input_names=["exemplar"],
                          output_names=["exemplar_feature"])
        torch.onnx.export(SearchGraph(net), (x, feat), str(ex_path), dynamo=False, opset_version=opset,
                          input_names=["search", "exemplar_feature"], output_names=["response"],
                          dynamic_axes={"search": {0: "scales", 1: "height", 2: "width"},
                                        "response": {0: "scales", 1: "rh", 2: "rw"}})
        # one id in both files: the runtime refuses an exemplar graph of another export beside the
        # search graph (a kill between AtomicFiles' two renames leaves such a pair)
        pair = {EXPORT_ID: export_id([ez_path, ex_path])}
        attach_metadata(ez_path, {**model_metadata(cfg, "siamfc-exemplar", extra_meta), **pair})
        attach_metadata(ex_path, {**model_metadata(cfg, "siamfc-search", extra_meta), **pair})
        if check is not None:
            check(ez_path, ex_path)
    return pz, px


def quantize_search(search_path: str | Path, out_path: str | Path, calib_crops: np.ndarray,
                    exemplar_feature: np.ndarray) -> Path:
    """Static QDQ int8 (uint8 activations, int8 per-channel weights, reduce_range for no-VNNI CPUs)
    of the search graph, calibrated on real search crops (N, H, W, 3) uint8."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.items = iter([{"search": calib_crops[i:i + 1], "exemplar_feature": exemplar_feature}
                               for i in range(len(calib_crops))])

        def get_next(self):
            return next(self.items, None)

    out_path = Path(out_path)
    pre = out_path.with_suffix(".pre.onnx")
    try:
        quant_pre_process(str(search_path), str(pre), skip_symbolic_shape=True)
        src = pre
    except Exception:
        src = Path(search_path)
    meta = {p.key: p.value for p in onnx.load(str(search_path)).metadata_props}
    import json
    m = json.loads(meta["track3d"])
    m["quantization"] = "int8 static QDQ, per-channel int8 weights, uint8 activations, reduce_range"
    # what `track3d-train quantize` records too: the runtime names int8 files in its refusals and
    # refuses a twin whose parent changed since (track3d.onnxmodel.made_from)
    m.update({"precision": "int8", **parent_fields(search_path)})
    try:
        with AtomicFiles(out_path) as (tmp,):   # written whole, with its metadata, or not at all
            # the correlation (MatMul with the exemplar) stays float: quantise the backbone convs only
            quantize_static(str(src), str(tmp), Reader(), quant_format=QuantFormat.QDQ,
                            activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True,
                            reduce_range=True, op_types_to_quantize=["Conv"])
            attach_metadata(tmp, m)
    finally:
        pre.unlink(missing_ok=True)
    return out_path


def parity(net: SiamFC, pz: str | Path, px: str | Path, seed: int = 0, scales: int | None = None,
           instance_size: int | None = None) -> dict:
    """Max abs difference torch vs onnxruntime for both graphs on random uint8 crops."""
    from track3d.onnxmodel import OnnxModel

    cfg = net.cfg
    g = torch.Generator().manual_seed(seed)
    s = scales or cfg.scale_num
    n = instance_size or cfg.instance_size
    z = torch.randint(0, 256, (1, cfg.exemplar_size, cfg.exemplar_size, 3), dtype=torch.uint8, generator=g)
    x = torch.randint(0, 256, (s, n, n, 3), dtype=torch.uint8, generator=g)
    net = net.eval()
    with torch.no_grad():
        fz = ExemplarGraph(net)(z)
        r_t = SearchGraph(net)(x, fz).numpy()
        r_ref = (net(net.normalise(z).expand(s, -1, -1, -1), net.normalise(x))[:, 0]).numpy()
    mz, mx = OnnxModel(pz, 1, "siamfc-exemplar"), OnnxModel(px, 1, "siamfc-search")
    fz_o = mz.run({"exemplar": z.numpy()})[0]
    r_o = mx.run({"search": x.numpy(), "exemplar_feature": fz_o})[0]
    out = {"exemplar_max_abs": float(np.abs(fz_o - fz.numpy()).max()),
           "exemplar_scale": float(np.abs(fz.numpy()).max()),
           "response_max_abs": float(np.abs(r_o - r_t).max()),
           "response_vs_conv_xcorr_max_abs": float(np.abs(r_t - r_ref).max()),
           "response_scale": float(np.abs(r_t).max()), "response_shape": list(r_o.shape)}
    require_parity(out, ("exemplar", "response"), "SiamFC")
    return out


def time_backbone(net: SiamFC, px: str | Path, scales: int, size: int, threads: int = 1,
                  repeats: int = 20) -> dict:
    """Median ms of the search graph: onnxruntime vs torch eager, same thread count."""
    from track3d.onnxmodel import OnnxModel

    cfg = net.cfg
    torch.set_num_threads(check_threads(threads))
    x = torch.randint(0, 256, (scales, size, size, 3), dtype=torch.uint8)
    net = net.eval()
    with torch.no_grad():
        fz = ExemplarGraph(net)(torch.randint(0, 256, (1, cfg.exemplar_size, cfg.exemplar_size, 3),
                                              dtype=torch.uint8))
        g = SearchGraph(net)
        tt = []
        for i in range(repeats + 3):
            t0 = time.perf_counter()
            g(x, fz)
            tt.append(time.perf_counter() - t0)
    m = OnnxModel(px, threads, "siamfc-search")
    feeds = {"search": x.numpy(), "exemplar_feature": fz.numpy()}
    to = []
    for i in range(repeats + 3):
        t0 = time.perf_counter()
        m.run(feeds)
        to.append(time.perf_counter() - t0)
    t_ms, o_ms = 1000 * float(np.median(tt[3:])), 1000 * float(np.median(to[3:]))
    return {"torch_ms": t_ms, "ort_ms": o_ms, "ratio_torch_over_ort": t_ms / o_ms, "threads": threads,
            "scales": scales, "size": size}
