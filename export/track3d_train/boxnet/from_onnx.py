"""An exported A3BoxNet (.onnx, e.g. the shipped model) back into PyTorch weights, to fine-tune it.

    model, ck = model_from_onnx("runtime/track3d/models/a3boxnet.onnx", calibration=points)

The export folds each per-point BatchNorm into the 1x1 convolution before it, so those layers
come back as the folded convolution plus a BatchNorm that is the identity in eval mode (the
converted model's outputs equal the ONNX graph's, within float32 noise). In training mode a
BatchNorm normalises by the batch's own statistics; an identity BatchNorm (weight 1, bias 0)
would then rescale every channel to unit variance and the fine-tune would start from another
function. With ``calibration`` (B, N, 3) centred points the BatchNorm of each folded layer takes
the channel mean and standard deviation of its input over those points as its bias and weight
(and running statistics), so a training-mode batch like them sees about the same function; eval
mode stays exact either way. The fully connected layers' BatchNorms are in the graph as they
are and load by name.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..onnx_meta import exported_weights, set_folded_bn

__all__ = ["model_from_onnx"]


def model_from_onnx(path: str | Path, calibration: np.ndarray | None = None):
    """-> (A3BoxNet in eval mode, checkpoint dict usable as ``train(init_from=...)``'s source).

    calibration: optional (B, N, 3) float32 centred points (B >= 2) for the folded layers'
    BatchNorm statistics (see the module docstring). Raises ValueError for a file that is not
    an A3BoxNet model or whose layers do not fit the architecture its metadata names."""
    import torch

    from .model import A3BoxNet, BoxNetConfig

    path = Path(path)
    meta, init, convs = exported_weights(path, "a3boxnet", "an A3BoxNet model")
    cfg = BoxNetConfig(num_points=int(meta["num_points"]), num_categories=int(meta["num_categories"]),
                       use_category=bool(meta["use_category"]), width=float(meta["width"]),
                       size_norm=str(meta.get("size_norm", "points")))
    model = A3BoxNet(cfg)
    conv_mods = [m for m in model.modules() if isinstance(m, torch.nn.Conv1d)]
    if len(conv_mods) != len(convs):
        raise ValueError(f"{path} has {len(convs)} convolutions, the architecture {len(conv_mods)}")
    state = model.state_dict()
    with torch.no_grad():
        for key in state:
            if key in init:
                if tuple(init[key].shape) != tuple(state[key].shape):
                    raise ValueError(f"{path}: {key} is {init[key].shape}, the architecture wants "
                                     f"{tuple(state[key].shape)}")
                state[key] = torch.from_numpy(np.array(init[key]))
        model.load_state_dict(state)
        folded = []   # (conv, its BatchNorm) in module order, matching the graph's Conv order
        for branch in (model.center_net, model.box_net):
            layers = list(branch.mlp)
            folded += [(layers[i], layers[i + 1]) for i in range(0, len(layers), 3)]
        for (conv, bn), (w, b) in zip(folded, convs):
            if tuple(w.shape) != tuple(conv.weight.shape):
                raise ValueError(f"{path}: a convolution is {w.shape}, the architecture wants "
                                 f"{tuple(conv.weight.shape)}")
            conv.weight.copy_(torch.from_numpy(np.array(w)))
            conv.bias.copy_(torch.from_numpy(np.array(b)) if b is not None else torch.zeros_like(conv.bias))
            set_folded_bn(bn, torch.zeros(bn.num_features), torch.ones(bn.num_features) - bn.eps)
        if calibration is not None:
            _calibrate(model, folded, calibration)
    model.eval()
    ck = {"model": model.state_dict(), "model_config": cfg.to_dict(), "epoch": -1, "step": 0,
          "imported_from": {"file": path.name, "exported": meta.get("exported"),
                            "train_data_hash": meta.get("train_data_hash"),
                            # None: a model exported before the metadata recorded its box coding
                            "size_norm": meta.get("size_norm"),
                            # the counts of a model trained beside the body's past views, else None
                            "past_views": meta.get("past_views")}}
    return model, ck


def _calibrate(model, folded, calibration) -> None:
    import torch

    pts = np.asarray(calibration, dtype=np.float32)
    if pts.ndim != 3 or pts.shape[2] != 3 or pts.shape[0] < 2 or pts.shape[1] < 1:
        raise ValueError(f"calibration points must be (B >= 2, N, 3), got {pts.shape}")
    stats = {}

    def hook(bn):
        def f(_m, inp, _out):
            x = inp[0].detach().double()
            stats[bn] = (x.mean(dim=(0, 2)), x.var(dim=(0, 2), unbiased=False))
        return f

    handles = [bn.register_forward_hook(hook(bn)) for _, bn in folded]
    model.eval()
    cat = torch.zeros(len(pts), model.config.num_categories) if model.config.use_category else None
    try:
        model(torch.from_numpy(pts), cat)   # eval: every folded BatchNorm is the identity here
    finally:
        for h in handles:
            h.remove()
    for _, bn in folded:
        mean, var = stats[bn]
        set_folded_bn(bn, mean.float(), var.float().clamp_min(1e-6))
