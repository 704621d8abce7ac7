"""`track3d-train quantize`: int8 twins of the shipped networks (static QDQ, onnxruntime.quantization).

    track3d-train quantize --data DATASET [--models-dir runtime/track3d/models] [--out-dir DIR]
                           [--models a3boxnet a3boxnet_narrow siamfc_edge siamfc_faithful] [--samples 300] [--force]

Writing over a shipped int8 file (the default --out-dir is the shipped models' folder, which
holds a3boxnet_int8.onnx) needs --force, as every export does.

For each fp32 model ``<stem>.onnx`` writes ``<stem>_int8.onnx`` (the file the runtime's loader
finds for ``precision="int8"``): static QDQ, uint8 activations, int8 per-channel weights
(full range: the runtime only picks int8 on CPUs with int8 dot-product instructions, where
reduce_range is not needed), calibrated (MinMax) on the TRAIN split of DATASET with the
runtime's own input preparation:

- A3BoxNet: frustum proposals of the ground-truth 2D boxes (``track3d.frustum.extract_frustum``),
  sampled and centred with ``A3BoxNetEstimator.sample`` and the model's size coding
  (``A3BoxNetEstimator.coding.normalise``, ``track3d.size_coding``);
  Conv + Gemm are quantised except the heads (the layers producing the outputs, ``head_nodes``);
- EdgeTrack: template and search crops cut as the tracker cuts them (normal and lost search
  sizes), each search crop with its sequence's template kernel; Conv quantised except the
  first layers and the heads (the correlation MatMul stays float);
- SiamFC: exemplar crops and search crops at the ground-truth boxes cut with
  ``track3d.siamfc.crop_square`` by the tracker's own geometry, each search crop paired with
  its sequence's exemplar feature; Conv is quantised (the correlation stays float).

The int8 file carries the parent's metadata plus ``precision``, ``quantization`` (recipe),
``parent_sha256`` (hash of the fp32 file: the runtime refuses the int8 file once the fp32 file
is re-exported, retrained or its metadata rewritten, ``track3d.onnxmodel.made_from``) and
``calibration`` (split, count, data hash: sha256 of the split's labels,
``track3d_train.boxnet.data.split_hash``). Whether a variant SHIPS is
decided by the accuracy rule in docs/models.md ("Arithmetic"), not here.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from track3d.onnxmodel import MODELS_DIR, variant_path

from track3d.argparsing import ArgumentParser, bounded

from .onnx_meta import attach_metadata, parent_fields, read_metadata, refuse_shipped

__all__ = ["QUANT_RECIPE", "calibration_boxnet", "calibration_siamfc", "calibration_edgetrack", "quantize_file",
           "build_parser", "main"]

QUANT_RECIPE = {"format": "QDQ", "method": "MinMax", "activations": "uint8", "weights": "int8 per channel",
                "reduce_range": False, "tool": "onnxruntime.quantization.quantize_static"}
SIAMFC_STEMS = {"siamfc_edge": "edge", "siamfc_faithful": "faithful"}
# the A3BoxNet files: the default (full width) and the half-width one distilled from it
BOXNET_STEMS = ("a3boxnet", "a3boxnet_narrow")


def _frames(root, split: str, samples: int, seed: int):
    """(sequence, frame index) pairs spread evenly over the split's visible frames."""
    from track3d.dataset import Dataset

    ds = Dataset(root)
    seqs = ds.sequences(split)
    if not seqs:
        raise FileNotFoundError(f"{root} has no {split} sequences")
    pairs = [(s, i) for s in seqs for i in range(len(s)) if not s.absent[i] and s.gt2d[i][2] >= 4 and s.gt2d[i][3] >= 4]
    rng = np.random.default_rng(seed)
    if len(pairs) > samples:
        pairs = [pairs[j] for j in sorted(rng.choice(len(pairs), samples, replace=False))]
    return ds, pairs


def calibration_boxnet(fp32: Path, root, split: str = "train", samples: int = 200, seed: int = 0) -> list[dict]:
    """Feeds of A3BoxNet from the split's frustum proposals (batch 1 each)."""
    from track3d.boxnet import INPUT_CATEGORY, INPUT_POINTS, A3BoxNetEstimator, one_hot
    from track3d.frames import point_bounds
    from track3d.frustum import extract_frustum

    est = A3BoxNetEstimator(fp32)
    ds, pairs = _frames(root, split, samples, seed)
    feeds = []
    for seq, i in pairs:
        pts = extract_frustum(seq.points(i), seq.gt2d[i].astype(np.float32), ds.camera.M)
        if len(pts) < 16:
            continue
        centred, _, _ = est.coding.normalise(est.sample(pts), np.stack(point_bounds(pts)))
        f = {INPUT_POINTS: centred[None].astype(np.float32)}
        if est._with_category:
            f[INPUT_CATEGORY] = one_hot([seq.category], est.num_categories)
        feeds.append(f)
    return feeds


def _siamese_feeds(trk, pairs, seed: int, template_feed, search_feed) -> tuple[list[dict], list[dict]]:
    """(template feeds, search feeds) of a Siamese tracker `trk` at the ground-truth boxes of
    `pairs`: the template crop of each frame, and a search crop around a centre shifted by up to
    a quarter of the target (the search region lies around the LAST centre) paired with its
    sequence's template output. template_feed(trk, img, avg) -> (feed, net input name, net);
    search_feed(trk, img, centre, avg, kernel, rng) -> feed."""
    import cv2

    rng = np.random.default_rng(seed)
    kernels: dict[str, np.ndarray] = {}
    tz, sx = [], []
    for seq, i in pairs:
        img = seq.image(i)
        trk._set_box(seq.gt2d[i])
        avg = tuple(float(c) for c in cv2.mean(img)[:3])
        feed, net = template_feed(trk, img, avg)
        tz.append(feed)
        if seq.name not in kernels:
            kernels[seq.name] = net.run(feed)[0]
        c = trk.center + rng.uniform(-0.25, 0.25, 2) * trk.target_sz
        sx.append(search_feed(trk, img, c, avg, kernels[seq.name], rng))
    return tz, sx


def calibration_siamfc(exemplar: Path, search: Path, root, split: str = "train", samples: int = 200,
                       seed: int = 0) -> tuple[list[dict], list[dict]]:
    """(exemplar feeds, search feeds) at the split's ground-truth boxes, cut as the tracker cuts
    (a random one of its search scales)."""
    from track3d.siamfc import SiamFCTracker, crop_square

    def template_feed(trk, img, avg):
        return {"exemplar": crop_square(img, trk.center, trk.z_sz, trk.exemplar_size, avg)[None]}, trk.exemplar

    def search_feed(trk, img, c, avg, kernel, rng):
        f = trk.scale_factors[rng.integers(len(trk.scale_factors))]
        return {"search": crop_square(img, c, trk.x_sz * f, trk.instance_size, avg)[None], "exemplar_feature": kernel}

    ds, pairs = _frames(root, split, samples, seed)
    return _siamese_feeds(SiamFCTracker(exemplar, search), pairs, seed, template_feed, search_feed)


def calibration_edgetrack(template: Path, search: Path, root, split: str = "train", samples: int = 200,
                          seed: int = 0) -> tuple[list[dict], list[dict]]:
    """(template feeds, search feeds) at the split's ground-truth boxes, cut as EdgeTrack cuts:
    the search crop at the tracked (normal) or, one time in five, the wider lost size, paired
    with its sequence's template kernel."""
    from track3d.edgetrack import EdgeTracker
    from track3d.siamfc import crop_square

    def template_feed(trk, img, avg):
        return {"template": crop_square(img, trk.center, trk._z_sz(), trk.exemplar_size, avg)[None]}, trk.template_net

    def search_feed(trk, img, c, avg, kernel, rng):
        size = trk.lost_instance_size if rng.random() < 0.2 else trk.instance_size
        scale = trk.exemplar_size / trk._z_sz()
        return {"search": crop_square(img, c, size / scale, size, avg)[None], "kernel": kernel}

    ds, pairs = _frames(root, split, samples, seed)
    return _siamese_feeds(EdgeTracker(template, search), pairs, seed, template_feed, search_feed)


def input_nodes(model, op_types: list[str]) -> list[str]:
    """Names of the `op_types` nodes fed by a graph input without another `op_types` node between:
    the first layers. A3BoxNet's see raw point coordinates in metres; 8 bits over their range
    are steps of several cm (measured: int8 first layers cost 0.007 AO_3d), so they stay float."""
    producers = {o: n for n in model.graph.node for o in n.output}
    inputs = {i.name for i in model.graph.input}
    firsts = []
    for n in model.graph.node:
        if n.op_type not in op_types:
            continue
        todo, seen = [n.input[0]], set()
        while todo:
            t = todo.pop()
            if t in inputs:
                firsts.append(n.name)
                break
            m = producers.get(t)
            if m is not None and m.op_type not in op_types and id(m) not in seen:
                seen.add(id(m))
                todo.extend(m.input)
    return firsts


def head_nodes(model, op_types: list[str]) -> list[str]:
    """Names of the `op_types` nodes whose output reaches a graph output without passing through
    another `op_types` node: the regression heads. Quantising their outputs puts the box
    residuals and centre offsets on an 8-bit grid (measured on A3BoxNet: steps of 0.09 of L,
    i.e. several % of the size), so they stay float."""
    consumers: dict[str, list] = {}
    for n in model.graph.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    outputs = {o.name for o in model.graph.output}
    heads = []
    for n in model.graph.node:
        if n.op_type not in op_types:
            continue
        todo, seen = list(n.output), set()
        while todo:
            t = todo.pop()
            if t in outputs:
                heads.append(n.name)
                break
            for c in consumers.get(t, []):
                if c.op_type not in op_types and id(c) not in seen:
                    seen.add(id(c))
                    todo.extend(c.output)
    return heads


CALIBRATIONS = ("minmax", "percentile", "entropy")


def quantize_file(fp32: Path, out: Path, feeds: list[dict], op_types: list[str], data_hash: str,
                  split: str, float_heads: bool = False, calibration: str = "minmax") -> Path:
    """Static QDQ int8 of `fp32` into `out`, calibrated on `feeds`, with the variant's metadata;
    float_heads: keep the first layers and the layers that produce the outputs in float
    (``input_nodes``, ``head_nodes``); calibration: how activation ranges are set from the
    samples ("minmax": their extremes; "percentile": the 99.999th percentile of |x|, so rare
    outliers do not widen every step; "entropy": the range that keeps the histogram's
    information)."""
    import onnx
    from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType,
                                          quantize_static)
    from onnxruntime.quantization.shape_inference import quant_pre_process

    class Reader(CalibrationDataReader):
        def __init__(self):
            self.items = iter(feeds)

        def get_next(self):
            return next(self.items, None)

    if not feeds:
        raise ValueError(f"no calibration data for {fp32.name}")
    methods = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile,
               "entropy": CalibrationMethod.Entropy}
    if calibration not in methods:
        raise ValueError(f"calibration must be one of {', '.join(methods)}, got {calibration!r}")
    out.parent.mkdir(parents=True, exist_ok=True)
    pre = out.with_name(out.stem + ".pre.onnx")
    try:
        quant_pre_process(str(fp32), str(pre), skip_symbolic_shape=True)
        src = pre
    except Exception:  # pre-processing is an optimisation; the plain graph quantises too
        src = fp32
    graph = onnx.load(str(src))
    exclude = sorted(set(head_nodes(graph, op_types) + input_nodes(graph, op_types))) if float_heads else []
    try:
        quantize_static(str(src), str(out), Reader(), quant_format=QuantFormat.QDQ,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, per_channel=True,
                        reduce_range=False, op_types_to_quantize=op_types, nodes_to_exclude=exclude,
                        calibrate_method=methods[calibration])
    finally:
        if pre.exists():
            pre.unlink()
    meta = read_metadata(onnx.load(str(fp32)))
    recipe = {**QUANT_RECIPE, "method": {"minmax": "MinMax", "percentile": "Percentile",
                                         "entropy": "Entropy"}[calibration]}
    meta.update({"precision": "int8", "quantization": {**recipe, "op_types": op_types,
                                                       "float_nodes": exclude},
                 **parent_fields(fp32),   # the runtime refuses this file once fp32 changes (made_from)
                 "calibration": {"split": split, "samples": len(feeds), "data_hash": data_hash}})
    attach_metadata(out, meta)
    return out


def _outputs(stem: str, models_dir: Path, out_dir: Path) -> list[tuple[Path, Path]]:
    """(fp32 file, int8 file it becomes) of a model stem."""
    parts = ([stem] if stem in BOXNET_STEMS else [f"{stem}_template", f"{stem}_search"] if stem == "edgetrack"
             else [f"{stem}_exemplar", f"{stem}_search"])
    return [(models_dir / f"{p}.onnx", out_dir / variant_path(models_dir / f"{p}.onnx", "int8").name) for p in parts]


def build_parser() -> argparse.ArgumentParser:
    ap = ArgumentParser(prog="track3d-train quantize", description=__doc__)
    ap.add_argument("--data", required=True, help="dataset root (track3d-sim output) with a train split")
    ap.add_argument("--split", default="train", help="calibration split (default: train)")
    ap.add_argument("--models-dir", type=Path, default=MODELS_DIR,
                    help="folder of the fp32 models (default: the shipped models)")
    ap.add_argument("--out-dir", type=Path, default=None, help="where the *_int8.onnx go (default: --models-dir)")
    ap.add_argument("--models", nargs="+", default=[*BOXNET_STEMS, "siamfc_edge", "siamfc_faithful"],
                    help=f"stems to quantise: {', '.join(BOXNET_STEMS)}, edgetrack, siamfc_edge, siamfc_faithful "
                         f"(default: {' '.join(BOXNET_STEMS)} siamfc_edge siamfc_faithful)")
    ap.add_argument("--samples", type=bounded(int, 1), default=300, help="calibration samples per network (default 300)")
    ap.add_argument("--seed", type=bounded(int, 0), default=0, help="sampling seed (default 0)")
    ap.add_argument("--calibration", choices=CALIBRATIONS, default="minmax",
                    help="activation ranges from the samples' extremes (minmax), a high percentile, or entropy")
    ap.add_argument("--force", action="store_true", help="overwrite shipped int8 models in track3d/models")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    unknown = [m for m in a.models if m not in (*BOXNET_STEMS, "edgetrack") and m not in SIAMFC_STEMS]
    if unknown:
        ap.error(f"unknown model stem(s) {', '.join(unknown)} "
                 f"(known: {', '.join(BOXNET_STEMS)}, edgetrack, {', '.join(SIAMFC_STEMS)})")
    out_dir = a.out_dir or a.models_dir
    # Before any calibration work: a shipped file is only replaced when asked.
    refuse_shipped([q for stem in a.models for _, q in _outputs(stem, a.models_dir, out_dir)], a.force, "--out-dir")
    from track3d.dataset import Dataset

    from .boxnet.data import split_hash

    data_hash = split_hash(Dataset(a.data), a.split)
    for stem in a.models:
        if stem in BOXNET_STEMS:
            [(fp32, q)] = _outputs(stem, a.models_dir, out_dir)
            feeds = calibration_boxnet(fp32, a.data, a.split, a.samples, a.seed)
            out = quantize_file(fp32, q, feeds, ["Conv", "Gemm"], data_hash, a.split, float_heads=True,
                                calibration=a.calibration)
            print(f"wrote {out} ({len(feeds)} calibration samples)")
        elif stem == "edgetrack":
            (pz, qz), (px, qx) = _outputs(stem, a.models_dir, out_dir)
            tz, sx = calibration_edgetrack(pz, px, a.data, a.split, a.samples, a.seed)
            for fp32, q, feeds in ((pz, qz, tz), (px, qx, sx)):
                # the correlation (MatMul with the kernel) and the heads' outputs stay float
                out = quantize_file(fp32, q, feeds, ["Conv"], data_hash, a.split, float_heads=True,
                                    calibration=a.calibration)
                print(f"wrote {out} ({len(feeds)} calibration samples)")
        else:
            (pz, qz), (px, qx) = _outputs(stem, a.models_dir, out_dir)
            ex, se = calibration_siamfc(pz, px, a.data, a.split, a.samples, a.seed)
            for fp32, q, feeds in ((pz, qz, ex), (px, qx, se)):
                out = quantize_file(fp32, q, feeds, ["Conv"], data_hash, a.split, calibration=a.calibration)
                print(f"wrote {out} ({len(feeds)} calibration samples)")
    return 0
