"""Differentiable lifting of heatmap pixels to 3D and their softmax aggregation (paper, Sec. 2.1-2.2).

For one person, every heatmap pixel m of every view v is a point: its original pixel coordinates
``uv (2,)``, the depth measured there ``depth`` (mm, 0 = unknown) and whether it may vote (``valid``: inside
the person's box and with known depth). The point is lifted along its camera ray,
``(D (u - cx) / fx, D (v - cy) / fy, D)``, and moved to the reference frame with T(v->0)
(:meth:`posenet.cameras.Camera.unproject`). The logits of invalid points are replaced by ``eps`` (a large
negative number, so their softmax weight is 0 in float32 while gradients stay finite). A softmax over all
V x M points per joint gives the weights a_i, and the joint is ``sum_i a_i p_i``.

**Confidence.** Beside each joint we return the weighted spread of its point cloud around the estimate,
``sqrt(sum_i a_i ||p_i - p_hat||^2)`` in mm. It is small when the network concentrates its mass on a compact
3D region (a confident, unimodal answer) and large when the mass is spread over the body, split between
views that disagree, or between two candidate places (e.g. left/right confusion). It is not a calibrated
error bar, but it ranks joints by reliability: larger means less trustworthy.

Everything is vectorised over persons, views, joints and points, and works for any V >= 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from posenet.cameras import Camera

Tensor = torch.Tensor

# The paper's epsilon: a large negative logit. exp(-1e4) underflows to exactly 0 in float32 and float64,
# unlike -inf it keeps softmax finite (and its gradient defined) when every point is masked.
EPS_LOGIT = -1e4


@dataclass
class JointEstimate:
    """The output of the aggregation.

    Attributes:
        joints: (P, J, 3) mm, reference frame.
        spread_mm: (P, J) mm, the weighted spread of each joint's point cloud (smaller = more certain; the
            calibration turns it into a confidence, ``posenet.net.calibration``).
        has_points: (P,) bool, whether the person had any valid point at all (else ``joints`` is meaningless).
    """

    joints: Tensor
    spread_mm: Tensor
    has_points: Tensor


def lift(cameras: Camera, uv: Tensor, depth: Tensor) -> Tensor:
    """Lift pixels to reference-frame points.

    Args:
        cameras: batch shape (V,) or (P, V).
        uv: (P, V, M, 2) original pixel coordinates (P may be 1 to share points between persons).
        depth: (P, V, M) mm along z.

    Returns:
        (P, V, M, 3) points in mm, reference frame.
    """
    if uv.ndim != 4 or uv.shape[-1] != 2 or depth.shape != uv.shape[:-1]:
        raise ValueError(
            f"lift expects uv (P, V, M, 2) and depth (P, V, M), got {tuple(uv.shape)}, {tuple(depth.shape)}"
        )
    if cameras.intrinsics.shape[-2] != uv.shape[1]:
        raise ValueError(
            f"{uv.shape[1]} views of points but cameras of batch shape {tuple(cameras.intrinsics.shape[:-1])}"
        )
    cams = cameras.to(device=uv.device, dtype=uv.dtype)
    # Camera.unproject's lifting, with T(v->0) applied as one (M, 3) x (3, 3) product per view: its
    # transform_points broadcasts R to every point (a 3x3 copy and product per point), 4/5 of the lift's time on a
    # frame's 175 k crop points (16 -> 3 ms at 1 thread; benchmarks/posenet_speed.py --frame).
    xy = cams.normalised(uv)  # (P, V, M, 2)
    points = torch.cat([xy * depth.unsqueeze(-1), depth.unsqueeze(-1)], dim=-1)  # (P, V, M, 3) camera frame
    T = cams.extrinsics  # (V, 4, 4) or (P, V, 4, 4)
    return torch.matmul(points, T[..., :3, :3].transpose(-1, -2)) + T[..., None, :3, 3]


def masked_logits(logits: Tensor, valid: Tensor, eps: float = EPS_LOGIT) -> Tensor:
    """Replace the logits ``(P, V, J, M)`` of invalid points ``valid (P, V, M)`` by ``eps``.

    Written as ``logits * keep + (1 - keep) * eps`` (one fused ``addcmul``): bit-identical to ``torch.where`` for
    finite logits, with the same gradient, and 4-5x faster on the CPU, where ``torch.where`` with a broadcast
    boolean mask is not vectorised (2.7 against 0.6 ms for 13 boxes x 10 joints x 9,216 points, one thread)."""
    keep = valid.unsqueeze(2).to(logits.dtype)
    return torch.addcmul((1 - keep) * eps, logits, keep)


def aggregate(logits: Tensor, points: Tensor, valid: Tensor, eps: float = EPS_LOGIT) -> JointEstimate:
    """Softmax over all views x points per joint, then the weighted sum of the points (the paper's joint).

    Args:
        logits: (P, V, J, M) network outputs at the points (any float dtype; computed in float32 or better).
        points: (P, V, M, 3) mm, reference frame (P may be 1: broadcast).
        valid: (P, V, M) bool (P may be 1: broadcast).

    Returns:
        :class:`JointEstimate` with joints (P, J, 3) and spread_mm (P, J).
    """
    if logits.ndim != 4 or points.ndim != 4 or valid.ndim != 3:
        raise ValueError(
            f"aggregate expects logits (P, V, J, M), points (P, V, M, 3), valid (P, V, M); got "
            f"{tuple(logits.shape)}, {tuple(points.shape)}, {tuple(valid.shape)}"
        )
    P, V, J, M = logits.shape
    dtype = torch.promote_types(logits.dtype, torch.float32)
    points = points.to(dtype).expand(P, V, M, 3)
    valid = valid.expand(P, V, M)
    z = masked_logits(logits.to(dtype), valid, eps)
    z = z.permute(0, 2, 1, 3).reshape(P, J, V * M)  # (P, J, V*M): one cloud per joint over all views
    weights = torch.softmax(z, dim=-1)
    flat = points.reshape(P, V * M, 3)  # (P, V*M, 3)
    # Centre the cloud on a fixed point near the person first: the spread E||p - p_hat||^2 =
    # E||q||^2 - ||q_hat||^2 (q = p - c) then involves metre-sized numbers, not room-sized ones, so float32
    # keeps ~0.1 mm^2; and no (P, J, V*M, 3) difference tensor is built (a few matrix products).
    w_valid = valid.reshape(P, V * M, 1).to(dtype)
    centre = ((flat * w_valid).sum(1) / w_valid.sum(1).clamp_min(1)).detach()  # (P, 3)
    q = flat - centre.unsqueeze(1)  # (P, V*M, 3)
    q_hat = weights @ q  # (P, J, 3)
    joints = q_hat + centre.unsqueeze(1)
    second = weights @ (q * q).sum(-1, keepdim=True)  # (P, J, 1): E_a ||q||^2
    spread = ((second.squeeze(-1) - (q_hat * q_hat).sum(-1)).clamp_min(0) + 1e-6).sqrt()
    return JointEstimate(joints, spread, valid.reshape(P, V * M).any(-1))


def centre_of_mass_2d(
    logits: Tensor, uv: Tensor, valid: Tensor, eps: float = EPS_LOGIT
) -> tuple[Tensor, Tensor]:
    """The 2D baseline's per-view estimate: a softmax within each view and the weighted mean pixel.

    Args:
        logits: (P, V, J, M); uv: (P, V, M, 2) original pixels; valid: (P, V, M).

    Returns:
        ``(uv_hat (P, V, J, 2), view_valid (P, V))``: the centre of mass per view and joint, and whether that
        view had any valid point.
    """
    P, V, J, M = logits.shape
    dtype = torch.promote_types(logits.dtype, torch.float32)
    weights = torch.softmax(masked_logits(logits.to(dtype), valid.expand(P, V, M), eps), dim=-1)
    uv_hat = weights @ uv.to(dtype).expand(P, V, M, 2)  # (P, V, J, 2)
    return uv_hat, valid.expand(P, V, M).any(-1)


def fuse_2d(
    logits: Tensor, uv: Tensor, depth: Tensor, valid: Tensor, cameras: Camera, eps: float = EPS_LOGIT
) -> JointEstimate:
    """The paper's 2D-loss baseline turned into 3D: per-view centre of mass, depth looked up, views fused.

    The depth at each view's 2D estimate is the depth of the nearest valid point (an index, so no gradient
    flows through it, as in the paper). The views are fused with a softmax over the logit found at that
    nearest point; views without valid points get ``eps``. Confidence is the weighted spread of the per-view
    3D estimates around the fused joint (mm).

    Args: as :func:`centre_of_mass_2d`, plus depth (P, V, M) and cameras of batch shape (V,) or (P, V).
    """
    P, V, J, M = logits.shape
    dtype = torch.promote_types(logits.dtype, torch.float32)
    uv_hat, view_valid = centre_of_mass_2d(logits, uv, valid, eps)
    uvx = uv.to(dtype).expand(P, V, M, 2)
    validx = valid.expand(P, V, M)
    dist = torch.cdist(uv_hat, uvx)  # (P, V, J, M)
    dist = torch.where(validx.unsqueeze(2), dist, torch.full_like(dist, float("inf")))
    nearest = dist.argmin(-1)  # (P, V, J)
    d = torch.gather(depth.to(dtype).expand(P, V, M), 2, nearest)  # (P, V, J)
    value = torch.gather(logits.to(dtype), 3, nearest.unsqueeze(-1)).squeeze(-1)  # (P, V, J)
    value = torch.where(view_valid.unsqueeze(-1), value, torch.full_like(value, eps))
    per_view = lift(cameras, uv_hat, d)  # (P, V, J, 3)
    w = torch.softmax(value, dim=1).unsqueeze(-1)  # (P, V, J, 1): fusion weights over views
    joints = (w * per_view).sum(1)  # (P, J, 3)
    spread = ((w * (per_view - joints.unsqueeze(1)) ** 2).sum((1, 3)) + 1e-6).sqrt()
    return JointEstimate(joints, spread, view_valid.any(-1))
