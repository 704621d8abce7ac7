"""The training objective of the paper's Appendix B.

L_joint = L_center-net + L_center_res + L_size_cls + L_size_res with

- L_center-net: Huber (delta 1) of alpha = |C_gt - (C_bar + dC1)|_2 (the stage-1 centre);
- L_center_res: Huber (delta 2) of beta = |C_gt - (C_bar + dC1 + dC2)|_2 (the final centre);
- L_size_cls: softmax cross-entropy over the 14 size classes;
- L_size_res: Huber (delta 1) of gamma = |R_gt - r * scale|_2, r the normalised residual the
  net predicts for the ground-truth class (as Frustum PointNets) and scale the length that
  makes it metres (max(S_gt) in the paper's coding, L of the points in ours).

Huber is applied to the Euclidean norm of the 3-vector, as the appendix writes it:
0.5 x^2 below delta, delta (x - delta / 2) above.

Optional, not the paper's: ``iou_weight`` adds w * (1 - IoU_3d) of the decoded box (centre and
the size of the predicted class, as the runtime decodes it) against the label's box: the joint
loss fits the hidden depth in metres, the evaluation scores it by overlap, and where the far
face is a guess the two reward different guesses.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

__all__ = ["huber_norm", "boxnet_loss", "distill_loss", "iou_3d", "decoded_sizes"]


def huber_norm(v: torch.Tensor, delta: float) -> torch.Tensor:
    """Huber of the L2 norm of the last axis: (..., k) -> (...). The quadratic branch is written
    with the squared norm so that the gradient at v = 0 is 0, not nan."""
    sq = (v * v).sum(dim=-1)
    n = torch.sqrt(sq + 1e-12)
    return torch.where(n < delta, 0.5 * sq, delta * (n - 0.5 * delta))


def iou_3d(ca: torch.Tensor, sa: torch.Tensor, cb: torch.Tensor, sb: torch.Tensor) -> torch.Tensor:
    """IoU of axis-aligned boxes given by centres (B, 3) and sizes (B, 3) -> (B,); the formula
    of track3d.boxes.iou_3d, written in torch so that it has a gradient (0 where disjoint)."""
    lo = torch.maximum(ca - sa / 2, cb - sb / 2)
    hi = torch.minimum(ca + sa / 2, cb + sb / 2)
    inter = torch.clamp(hi - lo, min=0.0).prod(dim=-1)
    union = sa.prod(dim=-1) + sb.prod(dim=-1) - inter
    return inter / torch.clamp(union, min=1e-12)


def decoded_sizes(cls: torch.Tensor, r: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Sizes (B, 3) in metres of class cls (B,) with normalised residual r (B, 3), as
    track3d.size_coding decodes them: per-axis scale (B, 3) -> scale * (1 + r) ("extent",
    "frustum"); a length (B,) -> (template[cls] + r) * L ("points"). Floored at 1 mm."""
    from track3d.boxes import SIZE_TEMPLATES
    from track3d.size_coding import MIN_LENGTH

    if scale.dim() == 2:
        s = scale * (1.0 + r)
    else:
        t = torch.as_tensor(SIZE_TEMPLATES, dtype=r.dtype, device=r.device)[cls]
        s = (t + r) * scale[:, None]
    return torch.clamp(s, min=MIN_LENGTH)


def boxnet_loss(outputs, center_rel: torch.Tensor, size_cls: torch.Tensor, size_res: torch.Tensor,
                scale: torch.Tensor, iou_weight: float = 0.0) -> tuple[torch.Tensor, dict[str, float]]:
    """outputs: (center1, center2, size_scores, size_residuals) of A3BoxNet;
    center_rel (B, 3): ground-truth centre minus the centroid of the input points;
    size_cls (B,) int64; size_res (B, 3) normalised residual label; scale (B,) metres, or (B, 3)
    per axis (the "extent" coding). iou_weight > 0 adds iou_weight * (1 - IoU_3d) of the decoded
    box (a coding whose label scale is its decoding scale: not "paper").
    Returns (batch-mean joint loss, {term: value})."""
    center1, center2, scores, residuals = outputs
    l_c1 = huber_norm(center_rel - center1, 1.0).mean()
    l_c2 = huber_norm(center_rel - (center1 + center2), 2.0).mean()
    l_cls = F.cross_entropy(scores, size_cls)
    r = residuals[torch.arange(len(size_cls), device=residuals.device), size_cls]
    l_res = huber_norm((size_res - r) * (scale if scale.dim() == 2 else scale[:, None]), 1.0).mean()
    total = l_c1 + l_c2 + l_cls + l_res
    terms = {"center1": l_c1.item(), "center2": l_c2.item(), "size_cls": l_cls.item(), "size_res": l_res.item()}
    if iou_weight > 0:
        idx = torch.arange(len(size_cls), device=residuals.device)
        pred_cls = scores.detach().argmax(dim=1)
        pred = decoded_sizes(pred_cls, residuals[idx, pred_cls], scale)
        truth = decoded_sizes(size_cls, size_res, scale)
        l_iou = (1.0 - iou_3d(center1 + center2, pred, center_rel, truth)).mean()
        total = total + iou_weight * l_iou
        terms["iou"] = l_iou.item()
    return total, {**terms, "total": total.item()}


def distill_loss(student, teacher, scale: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """How far a student's outputs are from a teacher's on the same inputs, in the terms of the
    joint loss: the stage-1 and final centres (Huber, metres), the size-class distribution
    (KL divergence of the student's softmax from the teacher's) and the residual of the
    teacher's class (Huber, metres via ``scale`` as in boxnet_loss). Zero when they agree."""
    s1, s2, s_scores, s_res = student
    t1, t2, t_scores, t_res = (o.detach() for o in teacher)
    l_c1 = huber_norm(t1 - s1, 1.0).mean()
    l_c2 = huber_norm((t1 + t2) - (s1 + s2), 2.0).mean()
    l_cls = F.kl_div(F.log_softmax(s_scores, dim=1), F.log_softmax(t_scores, dim=1), log_target=True,
                     reduction="batchmean")
    cls = t_scores.argmax(dim=1)
    idx = torch.arange(len(cls), device=s_res.device)
    l_res = huber_norm((t_res[idx, cls] - s_res[idx, cls]) * (scale if scale.dim() == 2 else scale[:, None]),
                       1.0).mean()
    total = l_c1 + l_c2 + l_cls + l_res
    return total, {"distill": total.item()}
