"""SiamFC in PyTorch: AlexNet-shaped backbone (width-scaled), cross-correlation head, loss.

Faithful variant (Bertinetto et al. 2016, the SiamFC the paper uses):
    conv 96@11 s2, BN, ReLU, maxpool 3 s2, conv 256@5 g2, BN, ReLU, maxpool 3 s2,
    conv 384@3, BN, ReLU, conv 384@3 g2, BN, ReLU, conv 256@3 g2 (no padding anywhere)
    exemplar 127 -> 6x6, search 255 -> 22x22, response 17x17, total stride 8.
Edge variant: the same graph with every width multiplied by `width` (e.g. 0.25).

The graphs exported for the runtime (see export.py) take uint8 RGB NHWC crops and normalise
inside, so the runtime never converts images to float itself.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

__all__ = ["SiamFCConfig", "VARIANTS", "Backbone", "SiamFC", "xcorr", "xcorr_matmul", "make_labels",
           "balanced_bce", "config_for"]

ALEXNET_WIDTHS = (96, 256, 384, 384, 256)


@dataclass
class SiamFCConfig:
    variant: str = "faithful"
    width: float = 1.0                 # multiplier on the AlexNet channel widths
    exemplar_size: int = 127
    instance_size: int = 255           # runtime search size (the net is fully convolutional)
    train_instance_size: int = 239     # search crop size during training (SiamFC: 255 - 2*8)
    total_stride: int = 8
    out_scale: float = 0.001           # small output scale of the cross-correlation head
    # input normalisation, applied inside the graphs: (x / 255 - mean) / std, RGB
    mean: tuple = (0.1, 0.1, 0.1)
    std: tuple = (0.15, 0.15, 0.15)
    # labels (training): positive within r_pos pixels (of the search crop) of the centre
    r_pos: float = 16.0
    # tracking hyper-parameters (SiamFC defaults, Bertinetto et al.; read by the runtime)
    context_amount: float = 0.5
    scale_num: int = 3
    scale_step: float = 1.0375
    scale_penalty: float = 0.9745
    scale_lr: float = 0.59
    window_influence: float = 0.176
    response_up: int = 16

    @property
    def channels(self) -> tuple[int, ...]:
        # every width even (grouped convs with 2 groups)
        return tuple(max(4, int(round(c * self.width / 2.0)) * 2) for c in ALEXNET_WIDTHS)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["mean"], d["std"] = list(self.mean), list(self.std)
        d["channels"] = list(self.channels)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SiamFCConfig":
        names = cls.__dataclass_fields__.keys()
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names}
        return cls(**kw)


VARIANTS = {
    "faithful": dict(variant="faithful", width=1.0, instance_size=255, scale_num=3),
    "edge": dict(variant="edge", width=0.25, instance_size=191, scale_num=1),
}


def config_for(variant: str, **overrides) -> SiamFCConfig:
    if variant not in VARIANTS:
        raise ValueError(f"unknown SiamFC variant {variant!r} (known: {', '.join(VARIANTS)})")
    kw = dict(VARIANTS[variant])
    kw.update({k: v for k, v in overrides.items() if v is not None})
    return SiamFCConfig(**kw)


def _bn(c):
    return nn.BatchNorm2d(c, eps=1e-6, momentum=0.05)


class Backbone(nn.Module):
    """AlexNet as in SiamFC, widths scaled by cfg.width. No padding: output = (in - 127)/8 + 6."""

    def __init__(self, cfg: SiamFCConfig):
        super().__init__()
        c1, c2, c3, c4, c5 = cfg.channels
        self.features = nn.Sequential(
            nn.Conv2d(3, c1, 11, 2), _bn(c1), nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2),
            nn.Conv2d(c1, c2, 5, 1, groups=2), _bn(c2), nn.ReLU(inplace=True),
            nn.MaxPool2d(3, 2),
            nn.Conv2d(c2, c3, 3, 1), _bn(c3), nn.ReLU(inplace=True),
            nn.Conv2d(c3, c4, 3, 1, groups=2), _bn(c4), nn.ReLU(inplace=True),
            nn.Conv2d(c4, c5, 3, 1, groups=2),
        )
        self.out_channels = c5
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                nn.init.zeros_(m.bias)

    def forward(self, x):
        return self.features(x)


def xcorr(z: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Batched cross-correlation: z (B, C, h, w) over x (B, C, H, W) -> (B, 1, H-h+1, W-w+1)."""
    b, c, h, w = x.shape
    out = F.conv2d(x.reshape(1, b * c, h, w), z, groups=b)
    return out.reshape(b, 1, out.shape[-2], out.shape[-1])


def xcorr_matmul(z: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """One exemplar z (1, C, k, k) over S search maps x (S, C, H, W) -> (S, 1, H-k+1, W-k+1).

    As a MatMul (k*k x C) x (C x H*W) and k*k shifted adds: on this CPU ~6x faster in
    onnxruntime than a Conv whose weight is a graph input. Slices use constant (negative)
    ends so the exported graph works for any search size.
    """
    c, k = z.shape[1], z.shape[-1]
    s, _, hh, ww = x.shape
    zm = z.reshape(c, k * k).transpose(0, 1)                   # (k*k, C)
    m = torch.matmul(zm, x.reshape(s, c, hh * ww))              # (S, k*k, H*W)
    m = m.reshape(s, k * k, hh, ww)
    out = None
    for a in range(k):
        for bb in range(k):
            ea = a - (k - 1) if a < k - 1 else None
            eb = bb - (k - 1) if bb < k - 1 else None
            t = m[:, a * k + bb, a:ea, bb:eb]
            out = t if out is None else out + t
    return out.unsqueeze(1)


class SiamFC(nn.Module):
    """Backbone + cross-correlation head. Training input: float tensors already normalised."""

    def __init__(self, cfg: SiamFCConfig):
        super().__init__()
        self.cfg = cfg
        self.backbone = Backbone(cfg)

    def normalise(self, x_uint8_nhwc: torch.Tensor) -> torch.Tensor:
        """uint8/float 0-255 (N, H, W, 3) RGB -> normalised float (N, 3, H, W)."""
        x = x_uint8_nhwc.permute(0, 3, 1, 2).float()
        mean = torch.tensor(self.cfg.mean, dtype=torch.float32).view(1, 3, 1, 1)
        std = torch.tensor(self.cfg.std, dtype=torch.float32).view(1, 3, 1, 1)
        return (x * (1.0 / 255.0) - mean) / std

    def forward(self, z: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """z (B, 3, 127, 127), x (B, 3, S, S), normalised -> logits (B, 1, R, R)."""
        return xcorr(self.backbone(z), self.backbone(x)) * self.cfg.out_scale


def make_labels(size: int, r_pos_cells: float, device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """SiamFC labels for a (size x size) response: 1 within r_pos_cells of the centre, else 0,
    and balanced weights (half the total weight on the positives, half on the negatives)."""
    r = torch.arange(size, dtype=torch.float32, device=device) - (size - 1) / 2.0
    dist = torch.sqrt(r.view(-1, 1) ** 2 + r.view(1, -1) ** 2)
    labels = (dist <= r_pos_cells).float()
    npos, nneg = labels.sum(), (1 - labels).sum()
    weights = torch.where(labels > 0, 0.5 / npos.clamp(min=1), 0.5 / nneg.clamp(min=1))
    return labels, weights


def balanced_bce(logits: torch.Tensor, r_pos_cells: float) -> torch.Tensor:
    """Balanced logistic loss of SiamFC for logits (B, 1, R, R) whose target sits at the centre."""
    labels, weights = make_labels(logits.shape[-1], r_pos_cells, logits.device)
    labels = labels.expand_as(logits[:, 0])
    loss = F.binary_cross_entropy_with_logits(logits[:, 0], labels, weight=weights.expand_as(labels),
                                              reduction="sum")
    return loss / logits.shape[0]
