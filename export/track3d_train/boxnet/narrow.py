"""A narrower A3BoxNet cut from a wider one, to fine-tune instead of training from scratch.

    ck = narrow_checkpoint(src_checkpoint, width=0.5)   # e.g. from model_from_onnx(...)[1]

Each hidden layer keeps the channels that matter most to the layer after it: channel j of a
layer scores |gamma_j| (its BatchNorm's scale: how far its normalised output swings) times the
L1 norm of the next layer's weights on it (how much the next layer listens). The kept channels'
weights, biases and BatchNorm parameters are copied as they are, and the next layer keeps only
their columns. The inputs (3 coordinates), the category inputs of the first fully connected
layer and the outputs are never cut. A channel whose BatchNorm scale and shift are both zero
outputs nothing, so cutting only such channels leaves the function unchanged (the test's hand
case); real channels are never quite silent, which is why the narrowed model is fine-tuned.
"""
from __future__ import annotations

import numpy as np

__all__ = ["narrow_checkpoint"]


def _layers(branch):
    """(weight-bearing layer, its BatchNorm or None) pairs of a PointNetBranch, input to output."""
    from torch import nn

    mods = list(branch.mlp) + list(branch.fc)
    out = []
    for i, m in enumerate(mods):
        if isinstance(m, (nn.Conv1d, nn.Linear)):
            bn = mods[i + 1] if i + 1 < len(mods) and isinstance(mods[i + 1], nn.BatchNorm1d) else None
            out.append((m, bn))
    return out


def _importance(bn, next_layer, n: int) -> np.ndarray:
    w = next_layer.weight.detach().reshape(next_layer.weight.shape[0], -1).abs().sum(0)[:n]
    return (bn.weight.detach().abs() * w).numpy()


def _narrow_branch(src, dst) -> None:
    import torch

    s_layers, d_layers = _layers(src), _layers(dst)
    if len(s_layers) != len(d_layers):
        raise ValueError("the two models do not have the same layers")
    n_mlp = sum(1 for m in src.mlp if isinstance(m, torch.nn.Conv1d))
    keep_in = np.arange(s_layers[0][0].weight.shape[1])
    with torch.no_grad():
        for i, ((ls, bs), (ld, bd)) in enumerate(zip(s_layers, d_layers)):
            n_src, n_dst = ls.weight.shape[0], ld.weight.shape[0]
            if n_dst > n_src:
                raise ValueError(f"cannot widen a layer ({n_src} -> {n_dst} channels)")
            if bs is None or n_dst == n_src:
                keep = np.arange(n_src)
            else:
                imp = _importance(bs, s_layers[i + 1][0], n_src)
                keep = np.sort(np.argsort(-imp, kind="stable")[:n_dst])
            k, kin = torch.from_numpy(keep), torch.from_numpy(keep_in)
            ld.weight.copy_(ls.weight[k][:, kin])
            ld.bias.copy_(ls.bias[k])
            if bs is not None:
                for name in ("weight", "bias", "running_mean", "running_var"):
                    getattr(bd, name).copy_(getattr(bs, name)[k])
            keep_in = keep
            if i == n_mlp - 1:   # the first FC layer also reads the category inputs after the pool
                extra = src.num_categories
                keep_in = np.concatenate([keep, n_src + np.arange(extra)]) if extra else keep


def narrow_checkpoint(src: dict, width: float) -> dict:
    """-> a checkpoint dict (``model``, ``model_config``, ...) of an A3BoxNet at ``width`` cut from
    ``src`` (a checkpoint dict of a wider model of the same N, category input and coding).

    Raises ValueError when ``width`` is not narrower than the source's."""
    from .model import A3BoxNet, BoxNetConfig

    cfg = dict(src["model_config"])
    if not 0 < width < float(cfg["width"]):
        raise ValueError(f"width {width} is not narrower than the source model's {cfg['width']}")
    big = A3BoxNet(BoxNetConfig(**cfg))
    big.load_state_dict(src["model"])
    small = A3BoxNet(BoxNetConfig(**{**cfg, "width": float(width)}))
    _narrow_branch(big.center_net, small.center_net)
    _narrow_branch(big.box_net, small.box_net)
    out = {k: v for k, v in src.items() if k not in ("model", "model_config")}
    out.update(model=small.state_dict(), model_config=small.config.to_dict(),
               narrowed_from={"width": float(cfg["width"])})
    return out
