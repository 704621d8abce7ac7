"""An exported EdgeTrack pair (e.g. the shipped one) back into PyTorch weights, to fine-tune it.

    net, ck = model_from_onnx("edgetrack")                       # the shipped pair, by name
    net, ck = model_from_onnx("runs/x/model/edgetrack", calibration=(z, x))   # a prefix or either file

The search graph holds every weight (the template graph runs the same backbone). The export
folds each BatchNorm into the convolution before it, so those layers come back as the folded
convolution's weight plus a BatchNorm carrying its bias that is otherwise the identity in eval
mode (the converted net's outputs equal the ONNX graph's within float32 noise). A fine-tune
trains in training mode, where a BatchNorm normalises by the batch's own statistics; an
identity BatchNorm would then rescale every channel to unit variance and the fine-tune would
start from another function. With ``calibration`` (template crops (B, 3, 128, 128), search crops
(B, 3, H, W), both normalised as the net's input) each BatchNorm takes the channel mean and
standard deviation of its input over those crops (both branches pooled, as a training step sees
them one after the other) as its bias and weight and as its running statistics, so a training
batch like them sees about the same function; eval mode stays exact either way (the same rule
as A3BoxNet's, ``track3d_train.boxnet.from_onnx``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..onnx_meta import exported_weights, set_folded_bn

__all__ = ["model_from_onnx", "is_exported_pair"]


def _search_path(source: str | Path) -> Path:
    """The search graph a source names: a prefix `<dir>/<name>`, either file of a pair, or the bare
    name of a shipped pair (e.g. "edgetrack")."""
    from track3d.edgetrack import model_paths
    from track3d.onnxmodel import model_pair

    p = Path(str(source))
    if p.suffix == ".onnx" and p.is_file() and not p.name.endswith("_template.onnx"):
        return p     # a search graph, or a file that is none (the caller says what it is)
    _, search = model_pair(str(source), None, None, ("template", "search"), model_paths)
    if not Path(search).is_file() and Path(str(source)).name == str(source):
        stem = Path(search).name[: -len("_search.onnx")]
        return model_paths(stem)[1]     # raises a one-line ModelError naming the shipped models
    return Path(search)


def is_exported_pair(source: str | Path) -> bool:
    """Whether `source` names an exported pair (ONNX) rather than a training checkpoint (.pt)."""
    s = str(source)
    if s.endswith(".onnx"):
        return True
    if Path(s).is_file():
        return False     # a file that is not .onnx: a checkpoint
    try:
        return _search_path(s).is_file()
    except Exception:    # noqa: BLE001 - not a pair; the checkpoint loader says what is wrong
        return False


def _graph(path: Path):
    if not path.is_file():
        raise FileNotFoundError(f"model file {path} does not exist")
    meta, _, convs = exported_weights(path, "edgetrack-search", "an EdgeTrack search graph")
    return meta, convs


def _conv_order(net, size: int):
    """The net's Conv2d modules in the order a search step runs them (the graph's Conv order)."""
    import torch

    order = []
    hooks = [m.register_forward_hook(lambda mod, i, o: order.append(mod))
             for m in net.modules() if isinstance(m, torch.nn.Conv2d)]
    try:
        with torch.no_grad():
            k = net.template(torch.zeros(1, 3, net.cfg.exemplar_size, net.cfg.exemplar_size))
            order.clear()
            net.track(k, torch.zeros(1, 3, size, size))
    finally:
        for h in hooks:
            h.remove()
    return order


def model_from_onnx(source: str | Path, calibration: tuple[np.ndarray, np.ndarray] | None = None):
    """-> (EdgeTrack in eval mode, checkpoint dict usable as ``train(init_from=...)``'s source).

    source: a prefix, either file of a pair, or a shipped pair's name. calibration: optional
    (template crops (B, 3, Hz, Wz), search crops (B, 3, Hx, Wx)) float32, normalised, B >= 2
    (see the module docstring). Raises ValueError for a file that is not an EdgeTrack search
    graph or whose layers do not fit the architecture its metadata names."""
    import torch

    from .model import EdgeTrack, EdgeTrackConfig

    path = _search_path(source)
    meta, convs = _graph(path)
    cfg = EdgeTrackConfig.from_dict(meta["config"])
    score = meta.get("score", {})
    cfg.calib_a, cfg.calib_b = float(score.get("a", cfg.calib_a)), float(score.get("b", cfg.calib_b))
    net = EdgeTrack(cfg).eval()
    order = _conv_order(net, cfg.instance_size)
    if len(order) != len(convs):
        raise ValueError(f"{path} has {len(convs)} convolutions, the architecture {len(order)}")
    bn_after = {}     # each bias-free conv -> the BatchNorm that follows it (the folded pairs)
    for mod in net.modules():
        kids = list(mod.children())
        for a, b in zip(kids, kids[1:]):
            if isinstance(a, torch.nn.Conv2d) and isinstance(b, torch.nn.BatchNorm2d):
                bn_after[a] = b
    with torch.no_grad():
        for conv, (w, b) in zip(order, convs):
            if tuple(w.shape) != tuple(conv.weight.shape):
                raise ValueError(f"{path}: a convolution is {w.shape}, the architecture wants "
                                 f"{tuple(conv.weight.shape)}")
            conv.weight.copy_(torch.from_numpy(np.array(w)))
            bias = torch.from_numpy(np.array(b)) if b is not None else torch.zeros(w.shape[0])
            bn = bn_after.get(conv)
            if bn is None:        # an output layer: its own bias
                conv.bias.copy_(bias)
            else:                 # folded: the BatchNorm is the identity plus the folded bias
                set_folded_bn(bn, torch.zeros(bn.num_features), torch.ones(bn.num_features) - bn.eps, bias)
        if calibration is not None:
            _calibrate(net, list(bn_after.items()), calibration)
    net.eval()
    ck = {"model": net.state_dict(), "config": cfg.to_dict(), "step": 0,
          "imported_from": {"file": path.name, "train_data_hash": meta.get("train_data_hash")}}
    return net, ck


def _calibrate(net, folded, calibration) -> None:
    import torch

    z, x = (np.asarray(a, dtype=np.float32) for a in calibration)
    if z.ndim != 4 or x.ndim != 4 or len(z) < 2 or len(z) != len(x) or z.shape[1] != 3 or x.shape[1] != 3:
        raise ValueError(f"calibration crops must be (B >= 2, 3, H, W) each, got {z.shape} and {x.shape}")
    sums = {}

    def hook(bn):
        def f(_m, inp, _out):
            t = inp[0].detach().double()
            n = t.shape[0] * t.shape[2] * t.shape[3]
            s, s2, c = sums.get(bn, (0.0, 0.0, 0))
            sums[bn] = (s + t.sum(dim=(0, 2, 3)), s2 + (t * t).sum(dim=(0, 2, 3)), c + n)
        return f

    handles = [bn.register_forward_hook(hook(bn)) for _, bn in folded]
    net.eval()
    try:
        with torch.no_grad():    # eval: every folded BatchNorm adds its bias only, so its input is the conv's
            net(torch.from_numpy(z), torch.from_numpy(x))
    finally:
        for h in handles:
            h.remove()
    for _, bn in folded:
        s, s2, c = sums[bn]
        mean = s / c
        var = (s2 / c - mean * mean).clamp_min(1e-6)
        shift = bn.bias.detach().double() - bn.running_mean.double()   # the folded bias
        set_folded_bn(bn, mean.float(), var.float(), shift.float())
