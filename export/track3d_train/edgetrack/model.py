"""EdgeTrack in PyTorch: a depthwise-separable Siamese tracker with pixel-wise correlation and
classification + box-regression heads, built for one CPU thread.

What makes the fast public CPU trackers fast, and what this net takes from them:
- a depthwise-separable backbone (3x3 depthwise + 1x1 pointwise), total stride 16, padding 1:
  template 128 -> 8x8 features, search 256 -> 16x16 (small maps, few MACs);
- the template branch runs once at init and is reduced to a (64, C) matrix, so the per-frame
  correlation is one MatMul (pixel-wise correlation: every template cell is a 1x1 kernel);
- the head sees the correlation maps and the search features, then a few depthwise-separable
  blocks and two 1x1 outputs: a target logit per cell and the box as distances (l, t, r, b) in
  search-crop pixels from the cell centre (anchor-free, FCOS style);
- one scale per frame: the box head tracks size changes, so no scale pyramid.

Cell (i, j) of an (n x n) map has its centre at (16 j + 8, 16 i + 8) in continuous crop
coordinates (pixel k spans [k, k+1)); `cell_centres` is the one implementation of that rule.
The exported graphs take uint8 RGB NHWC crops and normalise inside.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = ["EdgeTrackConfig", "EdgeTrack", "cell_centres", "make_targets", "edgetrack_loss"]


@dataclass
class EdgeTrackConfig:
    exemplar_size: int = 128          # template crop (context 0.5 around the target, as SiamFC)
    instance_size: int = 256          # search crop at run time (2 x the template's image extent)
    lost_instance_size: int = 336     # wider search while lost (same image scale; 384 measured 3-6x slower: caches)
    total_stride: int = 16
    widths: tuple = (16, 32, 64, 96)  # stem, then three stride-2 stages
    feat_channels: int = 64           # backbone output (correlation) channels
    head_channels: int = 64
    head_blocks: int = 2
    mean: tuple = (0.1, 0.1, 0.1)
    std: tuple = (0.15, 0.15, 0.15)
    # training labels: positive cells lie within this fraction of the half box (an ellipse)
    pos_radius: float = 0.5
    # tracking hyper-parameters (read by the runtime from the ONNX metadata)
    context_amount: float = 0.5
    window_influence: float = 0.35
    penalty_k: float = 0.1            # size / aspect change penalty (SiamRPN)
    size_lr: float = 0.4
    score_threshold: float = 0.5      # calibrated score below this: the target is lost
    # score calibration (Platt): score = sigmoid(a * logit + b), fitted on held-out pairs
    calib_a: float = 1.0
    calib_b: float = 0.0

    def to_dict(self) -> dict:
        d = asdict(self)
        for k in ("widths", "mean", "std"):
            d[k] = list(d[k])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "EdgeTrackConfig":
        names = cls.__dataclass_fields__.keys()
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names})


def _bn(c):
    return nn.BatchNorm2d(c, momentum=0.05)


class SepConv(nn.Sequential):
    """3x3 depthwise (stride s) + BN + ReLU, 1x1 pointwise + BN (+ ReLU)."""

    def __init__(self, cin, cout, stride=1, relu=True):
        layers = [nn.Conv2d(cin, cin, 3, stride, 1, groups=cin, bias=False), _bn(cin), nn.ReLU(inplace=True),
                  nn.Conv2d(cin, cout, 1, bias=False), _bn(cout)]
        if relu:
            layers.append(nn.ReLU(inplace=True))
        super().__init__(*layers)


class Backbone(nn.Module):
    """Stem conv 3x3 s2, then three stages of [SepConv s2, SepConv s1]: stride 16, padding 1."""

    def __init__(self, cfg: EdgeTrackConfig):
        super().__init__()
        w0, w1, w2, w3 = cfg.widths
        layers = [nn.Conv2d(3, w0, 3, 2, 1, bias=False), _bn(w0), nn.ReLU(inplace=True)]
        cin = w0
        for c in (w1, w2, w3):
            layers += [SepConv(cin, c, 2), SepConv(c, c, 1)]
            cin = c
        layers += [nn.Conv2d(cin, cfg.feat_channels, 1, bias=False), _bn(cfg.feat_channels)]
        self.body = nn.Sequential(*layers)

    def forward(self, x):
        return self.body(x)


class Head(nn.Module):
    """(pixel-wise correlation maps, search features) -> (logit (B, 1, n, n), ltrb (B, 4, n, n))."""

    def __init__(self, cfg: EdgeTrackConfig, n_kernels: int):
        super().__init__()
        c = cfg.head_channels
        self.fuse = nn.Sequential(nn.Conv2d(n_kernels + cfg.feat_channels, c, 1, bias=False), _bn(c),
                                  nn.ReLU(inplace=True))
        self.cls_tower = nn.Sequential(*[SepConv(c, c) for _ in range(cfg.head_blocks)])
        self.reg_tower = nn.Sequential(*[SepConv(c, c) for _ in range(cfg.head_blocks)])
        self.cls = nn.Conv2d(c, 1, 1)
        self.reg = nn.Conv2d(c, 4, 1)
        nn.init.normal_(self.cls.weight, std=0.01)
        nn.init.constant_(self.cls.bias, -2.0)      # most cells are background
        nn.init.normal_(self.reg.weight, std=0.01)
        nn.init.constant_(self.reg.bias, 0.5)
        self.stride = cfg.total_stride

    def forward(self, corr, feat):
        h = self.fuse(torch.cat([corr, feat], 1))
        logit = self.cls(self.cls_tower(h))
        # distances in crop pixels: exp keeps them positive, x stride puts 1 at one cell
        ltrb = torch.exp(self.reg(self.reg_tower(h)).clamp(-6.0, 6.0)) * self.stride
        return logit, ltrb


class EdgeTrack(nn.Module):
    """template(z) once -> kernel (B, K, C); track(kernel, x) -> (logit, ltrb) per frame."""

    def __init__(self, cfg: EdgeTrackConfig):
        super().__init__()
        self.cfg = cfg
        self.backbone = Backbone(cfg)
        k = (cfg.exemplar_size // cfg.total_stride) ** 2
        self.head = Head(cfg, k)
        self.register_buffer("mean", torch.tensor(cfg.mean, dtype=torch.float32).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(cfg.std, dtype=torch.float32).view(1, 3, 1, 1), persistent=False)

    def normalise(self, x_nhwc: torch.Tensor) -> torch.Tensor:
        """uint8/float 0-255 (N, H, W, 3) RGB -> normalised float (N, 3, H, W)."""
        return (x_nhwc.permute(0, 3, 1, 2).float() * (1.0 / 255.0) - self.mean) / self.std

    def template(self, z: torch.Tensor) -> torch.Tensor:
        """Normalised z (B, 3, 128, 128) -> kernel (B, K = 8*8, C), scaled by 1/sqrt(C)."""
        f = self.backbone(z)
        b, c = f.shape[:2]
        return f.reshape(b, c, -1).transpose(1, 2) * (c ** -0.5)

    def track(self, kernel: torch.Tensor, x: torch.Tensor):
        """kernel (B, K, C), normalised x (B, 3, H, W) -> logit (B, 1, n, n), ltrb (B, 4, n, n)."""
        f = self.backbone(x)
        b, c, h, w = f.shape
        corr = torch.matmul(kernel, f.reshape(b, c, h * w)).reshape(b, -1, h, w)
        return self.head(corr, f)

    def forward(self, z, x):
        return self.track(self.template(z), x)


def cell_centres(n: int, stride: int = 16, device=None) -> torch.Tensor:
    """Continuous crop coordinates of the n cell centres along one axis: stride * i + stride / 2."""
    return torch.arange(n, dtype=torch.float32, device=device) * stride + stride / 2.0


def make_targets(boxes: torch.Tensor, n: int, stride: int, pos_radius: float):
    """Labels for a batch. boxes (B, 4) [x0, y0, x1, y1] in search-crop pixels, NaN rows for
    negative pairs (no target). Returns cls (B, n, n) in {0, 1}, reg_mask (B, n, n) (cells inside
    the box, where the box is regressed) and ltrb targets (B, 4, n, n)."""
    b = boxes.shape[0]
    p = cell_centres(n, stride, boxes.device)
    px, py = p.view(1, 1, n), p.view(1, n, 1)
    x0, y0, x1, y1 = (boxes[:, k].view(b, 1, 1) for k in range(4))
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    hw, hh = ((x1 - x0) / 2).clamp(min=1.0), ((y1 - y0) / 2).clamp(min=1.0)
    # ellipse of half axes pos_radius * half box, at least one cell wide
    ax = torch.maximum(hw * pos_radius, torch.full_like(hw, stride * 0.75))
    ay = torch.maximum(hh * pos_radius, torch.full_like(hh, stride * 0.75))
    e = ((px - cx) / ax) ** 2 + ((py - cy) / ay) ** 2
    valid = torch.isfinite(boxes).all(1).view(b, 1, 1)
    cls = ((e <= 1.0) & valid).float()
    inside = (px > x0) & (px < x1) & (py > y0) & (py < y1)
    reg_mask = (inside | (e <= 1.0)) & valid
    ltrb = torch.stack([(px - x0).expand(b, n, n), (py - y0).expand(b, n, n),
                        (x1 - px).expand(b, n, n), (y1 - py).expand(b, n, n)], 1)
    return cls, reg_mask, ltrb.clamp(min=1.0)


def _iou_loss(pred, target):
    """1 - IoU of boxes given as (l, t, r, b) distances from the same point; (N, 4) each."""
    pl, pt, pr, pb = pred.unbind(1)
    tl, tt, tr, tb = target.unbind(1)
    inter = (torch.minimum(pl, tl) + torch.minimum(pr, tr)) * (torch.minimum(pt, tt) + torch.minimum(pb, tb))
    union = (pl + pr) * (pt + pb) + (tl + tr) * (tt + tb) - inter
    return 1.0 - inter / union.clamp(min=1e-6)


def edgetrack_loss(logit, ltrb, boxes, cfg: EdgeTrackConfig, reg_weight: float = 1.0) -> dict:
    """Balanced logistic loss on the cells (half the weight on positives, half on negatives,
    over the batch) + IoU loss of the boxes on cells inside the target. Returns the parts."""
    n = logit.shape[-1]
    cls, reg_mask, tgt = make_targets(boxes, n, cfg.total_stride, cfg.pos_radius)
    lg = logit[:, 0]
    npos, nneg = cls.sum().clamp(min=1), (1 - cls).sum().clamp(min=1)
    w = torch.where(cls > 0, 0.5 / npos, 0.5 / nneg)
    l_cls = F.binary_cross_entropy_with_logits(lg, cls, weight=w, reduction="sum")
    m = reg_mask.reshape(-1)
    if m.any():
        p = ltrb.permute(0, 2, 3, 1).reshape(-1, 4)[m]
        t = tgt.permute(0, 2, 3, 1).reshape(-1, 4)[m]
        l_reg = _iou_loss(p, t).mean()
    else:
        l_reg = lg.sum() * 0.0
    return {"loss": l_cls + reg_weight * l_reg, "cls": l_cls, "reg": l_reg}
