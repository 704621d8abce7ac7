"""A3BoxNet in PyTorch (paper section IV-B, Fig. 6): Frustum PointNets v1 without segmentation
and heading.

Both sub-networks share one PointNet form: per-point MLPs (1x1 convolutions + BN + ReLU),
a max-pool over points, the global feature concatenated with the one-hot coarse category,
and fully connected layers.

- centre regression net: centred points -> dC1 (stage-1 centre, relative to the centroid);
- amodal box estimation net: points minus dC1 -> dC2, 14 size-class scores, 14 x 3
  normalised size residuals.

Widths default to Frustum PointNets v1 (128-128-256 + FC 256-128-3 and 128-128-256-512 +
FC 512-256-out); ``width`` scales every layer (0.5 = the half-width edge variant).
The decoding of the outputs lives in the runtime (`track3d.boxnet`), not here.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from track3d.boxes import NUM_SIZE_CLASSES

__all__ = ["BoxNetConfig", "PointNetBranch", "A3BoxNet"]

CENTER_MLP, CENTER_FC = (128, 128, 256), (256, 128)
BOX_MLP, BOX_FC = (128, 128, 256, 512), (512, 256)


@dataclass
class BoxNetConfig:
    num_points: int = 1024
    num_categories: int = 3
    use_category: bool = True
    width: float = 1.0
    size_norm: str = "points"

    def to_dict(self) -> dict:
        return asdict(self)


def _w(channels, width: float) -> list[int]:
    return [max(8, int(round(c * width))) for c in channels]


class PointNetBranch(nn.Module):
    """Per-point MLP -> max-pool -> [global feature, one-hot category] -> FC layers -> out."""

    def __init__(self, mlp, fc, out: int, num_categories: int):
        super().__init__()
        layers, c = [], 3
        for k in mlp:
            layers += [nn.Conv1d(c, k, 1), nn.BatchNorm1d(k), nn.ReLU(inplace=True)]
            c = k
        self.mlp = nn.Sequential(*layers)
        layers, c = [], c + num_categories
        for k in fc:
            layers += [nn.Linear(c, k), nn.BatchNorm1d(k), nn.ReLU(inplace=True)]
            c = k
        layers.append(nn.Linear(c, out))
        self.fc = nn.Sequential(*layers)
        self.num_categories = num_categories

    def forward(self, points_bcn: torch.Tensor, category: torch.Tensor | None) -> torch.Tensor:
        g = self.mlp(points_bcn).amax(dim=2)
        if self.num_categories:
            g = torch.cat([g, category], dim=1)
        return self.fc(g)


class A3BoxNet(nn.Module):
    """forward(points (B, N, 3) centroid-subtracted, category (B, C) one-hot) ->
    center1 (B, 3), center2 (B, 3), size_scores (B, 14), size_residuals (B, 14, 3)."""

    def __init__(self, config: BoxNetConfig | None = None):
        super().__init__()
        self.config = cfg = config or BoxNetConfig()
        nc = cfg.num_categories if cfg.use_category else 0
        self.center_net = PointNetBranch(_w(CENTER_MLP, cfg.width), _w(CENTER_FC, cfg.width), 3, nc)
        self.box_net = PointNetBranch(_w(BOX_MLP, cfg.width), _w(BOX_FC, cfg.width), 3 + 4 * NUM_SIZE_CLASSES, nc)

    def forward(self, points: torch.Tensor, category: torch.Tensor | None = None):
        cat = category if self.config.use_category else None
        x = points.transpose(1, 2)                      # (B, 3, N)
        center1 = self.center_net(x, cat)               # stage-1 centre, relative to the centroid
        box = self.box_net(x - center1.unsqueeze(2), cat)
        ns = NUM_SIZE_CLASSES
        center2 = box[:, :3]
        size_scores = box[:, 3:3 + ns]
        size_residuals = box[:, 3 + ns:].reshape(-1, ns, 3)
        return center1, center2, size_scores, size_residuals
