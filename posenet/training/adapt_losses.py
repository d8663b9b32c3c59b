"""The label-free losses of ``posenet.training.adapt``: what calibrated multi-view RGB-D gives for free.

All distances are in mm, like the paper's MPJPE, so the losses can be summed with the supervised one on
rendered scenes without rescaling. Each is exactly 0 when its agreement holds, and finite (with a finite
gradient) when nothing qualifies.

- :func:`view_consistency`: for a person seen in >= 2 views, each view's own estimate (the softmax over that
  view's points only, :func:`per_view_estimates`) against the fused estimate of all views. The fused estimate is
  the **target, under stop-gradient**: the fused joint is a mix of the views' estimates weighted by each view's
  share of the softmax mass, so with a gradient through it the cheapest way to lower the loss would be to move
  mass between views (let one view dominate the fused joint and silence the others) instead of moving the views
  that disagree towards the consensus. With stop-gradient each view is pulled towards where the other views,
  fused, say the joint is, which is what a calibrated rig knows without labels.
- :func:`pseudo_labels` + :func:`posenet.net.loss.mpjpe`: the fused estimates of a teacher (an exponential moving
  average of the student, :func:`ema_update`) with the flip test, kept only where the teacher is certain, are
  3D targets for the paper's loss. The teacher runs without gradient (stop-gradient by construction) on
  un-augmented crops, the student on augmented ones; the augmentation is inverted before lifting, so one 3D
  target serves every augmentation.
- :func:`bone_loss`: the bone lengths of the fused estimate stay within the source data's per-bone mean +- one
  standard deviation (:func:`bone_statistics`, from the rendered source data's 3D poses; never the target's).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from posenet.net import lifting
from posenet.net.model import PoseOutput, average_flips
from posenet.skeleton import BONES

Tensor = torch.Tensor


def per_view_estimates(
    logits: Tensor, points: Tensor, valid: Tensor, eps: float = lifting.EPS_LOGIT
) -> lifting.JointEstimate:
    """Each view's own estimate: the softmax over that view's points only, then the weighted sum.

    Args:
        logits: (P, V, J, M); points: (P or 1, V, M, 3) mm, reference frame; valid: (P, V, M) bool.

    Returns:
        :class:`posenet.net.lifting.JointEstimate` with joints (P, V, J, 3), confidence (P, V, J) and has_points
        (P, V): whether that view had any valid point for the person.
    """
    if logits.ndim != 4 or points.ndim != 4 or valid.ndim != 3:
        raise ValueError(
            f"per_view_estimates expects logits (P, V, J, M), points (P, V, M, 3), valid (P, V, M); got "
            f"{tuple(logits.shape)}, {tuple(points.shape)}, {tuple(valid.shape)}"
        )
    P, V, J, M = logits.shape
    est = lifting.aggregate(
        logits.reshape(P * V, 1, J, M),
        points.expand(P, V, M, 3).reshape(P * V, 1, M, 3),
        valid.expand(P, V, M).reshape(P * V, 1, M),
        eps,
    )  # one "view" per (person, view): the softmax stays inside it
    return lifting.JointEstimate(
        est.joints.view(P, V, J, 3), est.spread_mm.view(P, V, J), est.has_points.view(P, V)
    )


def scene_view_estimates(out: PoseOutput, scene, eps: float = lifting.EPS_LOGIT) -> lifting.JointEstimate:
    """:func:`per_view_estimates` of the network's output ``out`` on ``scene`` (``posenet.net.inputs.SceneInput``):
    its pixels lifted through its cameras, on the device of the logits."""
    dev = out.logits.device
    points = lifting.lift(scene.cameras, scene.uv.to(dev), scene.depth.to(dev))  # (P or 1, V, M, 3)
    return per_view_estimates(out.logits, points, scene.valid.to(dev), eps)


def view_consistency(
    per_view: Tensor, view_ok: Tensor, fused: Tensor, min_views: int = 2, stop_gradient: bool = True
) -> Tensor:
    """Distances (mm) between each view's estimate and the fused one, for persons seen in >= ``min_views`` views.

    Args:
        per_view: (P, V, J, 3) the views' own estimates; view_ok: (P, V) views with valid points;
        fused: (P, J, 3) the fused estimate (detached when ``stop_gradient``; see the module docstring).

    Returns:
        (K,) the distances of the qualifying (person, view, joint) triples; the loss is their mean.
    """
    P, V, J, _ = per_view.shape
    if view_ok.shape != (P, V) or fused.shape != (P, J, 3):
        raise ValueError(
            f"view_consistency expects view_ok (P, V) and fused (P, J, 3) for per_view {tuple(per_view.shape)}; "
            f"got {tuple(view_ok.shape)}, {tuple(fused.shape)}"
        )
    target = fused.detach() if stop_gradient else fused
    dist = (per_view - target.unsqueeze(1)).norm(dim=-1)  # (P, V, J)
    use = view_ok & (view_ok.sum(1, keepdim=True) >= min_views)  # (P, V)
    return dist[use.unsqueeze(-1).expand(P, V, J)]


def mean_or_zero(values: list[Tensor], like: Tensor) -> Tensor:
    """The mean of the concatenated ``values``; a 0 that keeps ``like``'s graph when there are none."""
    flat = torch.cat([v.reshape(-1) for v in values]) if values else like.new_zeros(0)
    return flat.mean() if flat.numel() else like.sum() * 0.0


@dataclass
class PseudoLabels:
    """joints (P, J, 3) mm, the teacher's flip-averaged fused estimate; keep (P, J) the joints certain enough
    to be targets; uncertainty (P, J) mm, what was thresholded."""

    joints: Tensor
    keep: Tensor
    uncertainty: Tensor


def pseudo_labels(plain: PoseOutput, mirrored: PoseOutput, max_uncertainty: float) -> PseudoLabels:
    """3D targets from the teacher's two passes (plain and mirrored inputs, both already un-flipped).

    A joint's uncertainty is its point cloud's spread (``posenet.net.lifting``'s ``spread_mm``), averaged over the two
    passes, plus half the distance between the two passes' joints (the flip test's disagreement: a left/right
    confusion shows up there even when each pass is peaked). Joints at or below ``max_uncertainty`` mm are kept.
    """
    both = average_flips(plain, mirrored)
    uncertainty = both.spread_mm + 0.5 * (plain.joints - mirrored.joints).norm(dim=-1)  # (P, J)
    keep = (uncertainty <= max_uncertainty) & both.has_points.unsqueeze(-1)
    return PseudoLabels(both.joints.detach(), keep, uncertainty.detach())


def bone_lengths(joints: Tensor) -> Tensor:
    """(..., J, 3) -> (..., B) lengths of :data:`posenet.skeleton.BONES`, mm."""
    a, b = torch.tensor(BONES, device=joints.device).unbind(-1)
    return (joints[..., a, :] - joints[..., b, :]).norm(dim=-1)


def bone_statistics(poses: Tensor, valid: Tensor) -> tuple[Tensor, Tensor]:
    """Per-bone mean and standard deviation (mm) over the bones of ``poses (N, J, 3)`` whose two joints are
    ``valid (N, J)``: ``(mean (B,), std (B,))``. Raises ValueError when a bone is never annotated."""
    a, b = torch.tensor(BONES).unbind(-1)
    lengths = bone_lengths(poses.double())  # (N, B)
    ok = (valid[:, a] & valid[:, b]).double()  # (N, B)
    n = ok.sum(0)
    if (n < 2).any():
        raise ValueError(f"the source poses annotate some bone fewer than twice (counts {n.tolist()})")
    mean = (lengths * ok).sum(0) / n
    var = (((lengths - mean) ** 2) * ok).sum(0) / (n - 1)
    return mean.float(), var.sqrt().float()


def bone_loss(joints: Tensor, person_ok: Tensor, mean: Tensor, std: Tensor, tolerance: float = 1.0) -> Tensor:
    """Distances (mm) by which the bones of ``joints (P, J, 3)`` leave ``mean +- tolerance * std``, for the
    persons ``person_ok (P,)``: (K,) values, 0 inside the band; the loss is their mean."""
    excess = ((bone_lengths(joints) - mean.to(joints)).abs() - tolerance * std.to(joints)).clamp_min(
        0
    )  # (P, B)
    return excess[person_ok]


@torch.no_grad()
def ema_update(teacher: torch.nn.Module, student: torch.nn.Module, momentum: float) -> None:
    """teacher <- momentum * teacher + (1 - momentum) * student, for every floating-point weight and buffer
    (BatchNorm's running statistics too); integer buffers (batch counters) are copied."""
    if not 0.0 <= momentum <= 1.0:
        raise ValueError(f"momentum must be in [0, 1], got {momentum}")
    t_state, s_state = teacher.state_dict(), student.state_dict()
    if t_state.keys() != s_state.keys():
        raise ValueError("teacher and student have different weights")
    for name, t in t_state.items():
        s = s_state[name]
        if t.is_floating_point():
            t.mul_(momentum).add_(s, alpha=1.0 - momentum)
        else:
            t.copy_(s)
