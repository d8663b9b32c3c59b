"""Training losses: the paper's MPJPE in 3D, and the 2D-loss baseline it is compared with (paper, Table 1).

- ``3d`` (the method): the mean Euclidean distance, in mm, between predicted and annotated joints, over the
  annotated joints only. The gradient flows back through aggregation, lifting, the inverse augmentation
  and the U-Net.
- ``2d`` (the baseline): each view's heatmap is reduced to a 2D centre of mass
  (:func:`posenet.net.lifting.centre_of_mass_2d`) and compared, in pixels, with the annotated joint projected
  into that view; only views in which the person has a box count. At test time this baseline gets its
  3D joints from :func:`posenet.net.lifting.fuse_2d`.
"""

from __future__ import annotations

import torch

from posenet.cameras import Camera

Tensor = torch.Tensor


def mpjpe(pred: Tensor, target: Tensor, valid: Tensor) -> Tensor:
    """Mean per-joint position error over valid joints: ``pred, target (P, J, 3)`` mm, ``valid (P, J)`` bool.

    Returns a scalar in mm (0 with a zero gradient when nothing is valid, so a scene without annotations is a
    no-op step instead of a NaN).
    """
    if pred.shape != target.shape or pred.shape[:-1] != valid.shape or pred.shape[-1] != 3:
        raise ValueError(
            f"mpjpe expects pred, target (P, J, 3) and valid (P, J); got {tuple(pred.shape)}, "
            f"{tuple(target.shape)}, {tuple(valid.shape)}"
        )
    dist = (pred - target.to(pred)).norm(dim=-1)  # (P, J)
    w = valid.to(pred.dtype)
    return (dist * w).sum() / w.sum().clamp_min(1)


def reprojection_2d(
    uv_hat: Tensor, target: Tensor, valid: Tensor, view_valid: Tensor, cameras: Camera
) -> Tensor:
    """The 2D baseline's loss in pixels.

    Args:
        uv_hat: (P, V, J, 2) per-view centres of mass, original pixels.
        target: (P, J, 3) mm, reference frame; valid: (P, J) bool.
        view_valid: (P, V) views in which the person has a box.
        cameras: batch shape (V,).
    """
    P, V, J, _ = uv_hat.shape
    cams = cameras.to(device=uv_hat.device, dtype=uv_hat.dtype)
    gt_uv = cams.project(target.to(uv_hat).unsqueeze(1).expand(P, V, J, 3))  # (P, V, J, 2)
    dist = (uv_hat - gt_uv).norm(dim=-1)  # (P, V, J)
    w = (valid.unsqueeze(1) & view_valid.unsqueeze(2)).to(dist.dtype)
    return (dist * w).sum() / w.sum().clamp_min(1)
