"""The pose network's output per detected box, lifted box by box or regrouped into persons without running it again.

The U-Net reads one (box, view) pair at a time: its input is that view's crop (or image) with that box's mask,
whatever other boxes the person has. So the heatmaps of every box of a frame can be computed once, before the
boxes are grouped into persons, and then

- lifted **alone**: the softmax over that box's own pixels gives a single-view 3D skeleton per box (what the
  skeleton matcher, ``pipeline.skeleton_matching``, compares across views);
- **regrouped**: a person made of any set of boxes (one per view, or two boxes of one view that the detector
  split) gets the usual softmax over all its boxes' points, exactly what ``PoseEstimator.predict`` gives for
  those boxes, from the same heatmaps.

Usage::

    heat = estimator.box_heatmaps(views, boxes)       # boxes: V arrays (K_v, 4); the U-Net runs once here
    alone = heat.single_view()                        # joints (N, J, 3) of the N = sum K_v boxes, view order
    persons = heat.estimate(members)                  # members (P, S): box numbers of each person, -1 = none

With flip averaging (``ModelConfig.flip_test``) both passes are kept and every estimate is the mean of the two,
as ``posenet.net.model.average_flips`` does.

**Any grouping at the cost of a few sums.** The paper's joint is a softmax over the points of all the person's
boxes. A softmax over a union of clouds is the softmax over each cloud, weighted by the softmax of the clouds'
log-sum-exps; its mean is the weighted mean of the clouds' means, and its spread follows from the clouds' spreads
and means (the law of total variance). So each box's cloud is reduced once, per joint, to its log-sum-exp, mean
and variance (``BoxPass.moments``), and every estimate afterwards (each box alone, each person, each person
without one of its boxes) combines a handful of those: no softmax over 9,216 points per box is repeated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from posenet.cameras import Camera
from posenet.net import augment as aug
from posenet.net import lifting
from posenet.net.inputs import InputConfig, SceneInput, build_box_crops, build_scene
from posenet.net.lifting import JointEstimate

Tensor = torch.Tensor


@dataclass
class BoxPass:
    """One pass (plain or mirrored) of the U-Net over the N boxes, in the frame's box order.

    logits (N, J, M) at the points uv (N, M, 2) with depth (N, M) and valid (N, M); points (N, M, 3) mm in the
    reference frame, lifted once here for the 3D aggregation (None for the 2D baseline, which lifts per joint)."""

    logits: Tensor
    uv: Tensor
    depth: Tensor
    valid: Tensor
    points: Tensor | None = None
    _moments: tuple[Tensor, Tensor, Tensor, Tensor] | None = field(default=None, repr=False)

    def moments(self, eps: float) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Per box and joint the softmax cloud's log-sum-exp (N, J), mean (N, J, 3) mm and variance (N, J) mm^2
        (float64), over the box's points with invalid ones at logit ``eps``, as ``lifting.aggregate``; and per
        box whether it has a valid point at all (N,)."""
        if self._moments is None:
            with torch.inference_mode():
                z = lifting.masked_logits(self.logits[:, None].float(), self.valid[:, None], eps)[
                    :, 0
                ]  # (N, J, M)
                weights = torch.softmax(z, dim=-1)
                # the log-sum-exp from the softmax at its largest logit: lse = z_max - log(w_max)
                lse = z.amax(-1) - weights.amax(-1).log()  # (N, J)
                # the geometry laid out (N, 3, M), so that every reduction runs along contiguous points
                points = self.points.float().permute(0, 2, 1).contiguous()  # (N, 3, M)
                # centred on each box's valid points (metre-sized numbers in float32, as aggregate does)
                w_valid = self.valid.float().unsqueeze(1)  # (N, 1, M)
                centre = (points * w_valid).sum(-1) / w_valid.sum(-1).clamp_min(1)  # (N, 3)
                # the first and second moments in one product with [q, |q|^2] (N, 4, M): a batched product
                # with 4 columns of stride 4 runs 3-4x slower on the CPU than with contiguous rows
                basis = points.new_empty(points.shape[0], 4, points.shape[2])
                q = torch.sub(points, centre.unsqueeze(-1), out=basis[:, :3])  # (N, 3, M)
                torch.sum(q * q, 1, out=basis[:, 3])
                m = weights @ basis.transpose(1, 2)  # (N, J, 4)
                first = m[..., :3]
                var = (m[..., 3] - (first * first).sum(-1)).clamp_min(0)
                self._moments = (
                    lse.double(),
                    (first + centre.unsqueeze(1)).double(),
                    var.double(),
                    self.valid.any(-1),
                )
        return self._moments


@dataclass
class BoxHeatmaps:
    """The per-box network outputs of one frame.

    Attributes:
        view: (N,) the view of each box; boxes are numbered in view order, then in their order within the view.
        index: (N,) each box's index within its view.
        cameras: batch shape (V,), of the images the points refer to.
        passes: one :class:`BoxPass`, two with flip averaging.
        estimate_fn: the model's ``PoseNet.estimate`` (the 2D baseline's fusion, when ``points`` is None).
        eps: the model's logit for points that may not vote.
    """

    view: Tensor
    index: Tensor
    cameras: Camera
    passes: list[BoxPass]
    estimate_fn: object
    eps: float = lifting.EPS_LOGIT
    _single: JointEstimate | None = field(default=None, init=False, repr=False)

    def reduce(self) -> None:
        """Reduce every box's clouds to their softmax moments now (:meth:`BoxPass.moments`): the per-box half of
        the fusion, which every later estimate (single views, persons, leave-one-out) reuses."""
        for p in self.passes:
            if p.points is not None:
                p.moments(self.eps)

    @property
    def num_boxes(self) -> int:
        return int(self.view.shape[0])

    def estimate(self, members: Tensor | np.ndarray | Sequence[Sequence[int]]) -> JointEstimate:
        """Joints of persons made of boxes.

        Args:
            members: (P, S) box numbers (0..N-1) of each person, -1 for unused slots; a box may serve several
                persons, and a person may hold several boxes of one view.

        Returns:
            joints (P, J, 3) mm reference frame, spread_mm (P, J) mm, has_points (P,).
        """
        members = torch.as_tensor(np.asarray(members, np.int64) if not torch.is_tensor(members) else members)
        if members.ndim != 2:
            raise ValueError(f"members must be (P, S) box numbers, got shape {tuple(members.shape)}")
        if members.numel() and int(members.max()) >= self.num_boxes:
            raise ValueError(f"members name box {int(members.max())} of {self.num_boxes}")
        if all(p.points is not None for p in self.passes):  # the 3D aggregation: from the boxes' moments
            return self._fuse(members.numpy())
        size = (members >= 0).sum(1)  # (P,)
        parts = []
        # Persons are fused in buckets of equal box count, each padded only to its own count (one person with
        # many boxes does not pad every other person's softmax).
        for s in size.unique().tolist():
            rows = torch.nonzero(size == s).squeeze(1)
            part = members[rows]
            part = part.gather(1, torch.argsort((part < 0).to(torch.int8), dim=1, stable=True))[
                :, : max(s, 1)
            ]
            parts.append((rows, self._estimate(part)))
        P, J = members.shape[0], self.passes[0].logits.shape[1]
        out = JointEstimate(torch.zeros(P, J, 3), torch.zeros(P, J), torch.zeros(P, dtype=torch.bool))
        for rows, est in parts:
            out.joints[rows], out.spread_mm[rows], out.has_points[rows] = (
                est.joints.cpu().float(),
                est.spread_mm.cpu().float(),
                est.has_points.cpu(),
            )
        return out

    def _estimate(self, members: Tensor) -> JointEstimate:
        """:meth:`estimate` of persons padded to one slot count S, members (P, S), for the 2D baseline (which
        lifts per joint from the pixels)."""
        used = members >= 0  # (P, S)
        slot = members.clamp_min(0)  # (P, S)
        cams = self.cameras[self.view[slot]]  # batch (P, S)
        if members.shape[1] == 1 and torch.equal(members[:, 0], torch.arange(self.num_boxes)):
            take = lambda x: x.unsqueeze(1)  # noqa: E731  every box alone, in order: a view, no gather copy
        else:
            take = lambda x: x[slot]  # noqa: E731
        outs = []
        with torch.inference_mode():
            for p in self.passes:
                valid = take(p.valid) & used.unsqueeze(-1)  # (P, S, M)
                outs.append(self.estimate_fn(take(p.logits), take(p.uv), take(p.depth), valid, cams))
        joints = torch.stack([o.joints for o in outs]).mean(0)
        spread = torch.stack([o.spread_mm for o in outs]).mean(0)
        has_points = torch.stack([o.has_points for o in outs]).all(0)
        return JointEstimate(joints, spread, has_points)

    def _fuse(self, members: np.ndarray) -> JointEstimate:
        """``lifting.aggregate`` over each person's boxes ``members (P, S)`` (-1: no box), from the boxes' moments:
        a softmax over the union of clouds is each cloud's softmax weighted by its log-sum-exp. A person is a few
        boxes of a few numbers each, so this is numpy (torch's per-call overhead would dominate), without buckets.
        """
        if members.shape[1] == 0:  # no slots at all: one empty slot each
            members = np.full((len(members), 1), -1, np.int64)
        used = members >= 0  # (P, S)
        slot = np.maximum(members, 0)
        joints, spread, has_points = [], [], []
        for p in self.passes:
            lse, mean, var, has = (m.numpy() for m in p.moments(self.eps))
            logw = np.where(used[..., None], lse[slot], -np.inf)  # (P, S, J)
            top = logw.max(1, keepdims=True)
            w = np.exp(logw - np.where(np.isfinite(top), top, 0.0))
            total = w.sum(1, keepdims=True)
            w = np.divide(
                w, total, out=np.zeros_like(w), where=total > 0
            )  # a person without boxes: weights 0
            mu = mean[slot]  # (P, S, J, 3)
            fused = (w[..., None] * mu).sum(1)  # (P, J, 3)
            joints.append(fused.astype(np.float32))
            s2 = (w * (var[slot] + ((mu - fused[:, None]) ** 2).sum(-1))).sum(1)  # (P, J)
            spread.append(np.sqrt(s2 + 1e-6).astype(np.float32))
            has_points.append((has[slot] & used).any(1))
        return JointEstimate(
            torch.from_numpy(np.mean(joints, 0, dtype=np.float32)),
            torch.from_numpy(np.mean(spread, 0, dtype=np.float32)),
            torch.from_numpy(np.all(has_points, 0)),
        )

    def joint_bounds(self, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Per joint the axis-aligned box ``(lo (J, 3), hi (J, 3))``, mm, around the softmax means of ``boxes``
        (box numbers, or an (N,) bool mask) in every pass: any person fused from some of them lies inside it (a
        fused joint is a weighted mean of its boxes' means, averaged over the passes). None without the 3D
        aggregation or without boxes."""
        if not all(p.points is not None for p in self.passes):
            return None
        means = np.stack([p.moments(self.eps)[1].numpy()[boxes] for p in self.passes])  # (passes, n, J, 3)
        if not means.shape[1]:
            return None
        return means.min((0, 1)), means.max((0, 1))

    def single_view(self) -> JointEstimate:
        """Each box lifted alone: joints (N, J, 3), spread_mm (N, J), has_points (N,); computed once (the
        matcher reads it again for the boxes it left over), so treat it as read-only."""
        if self._single is None:
            self._single = self.estimate(torch.arange(self.num_boxes)[:, None])
        return self._single


def slot_layout(boxes: Sequence[np.ndarray]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Lay the boxes of V views out as a scene of K = max K_v "persons": slot (k, v) holds box k of view v.

    Returns ``(boxes (K, V, 4), has_box (K, V), view (N,), index (N,))`` with N = sum K_v in view order.
    """
    per_view = [np.asarray(b, np.float32).reshape(-1, 4) for b in boxes]
    counts = [len(b) for b in per_view]
    K, V = max(counts, default=0), len(per_view)
    dense = torch.zeros(K, V, 4)
    has = torch.zeros(K, V, dtype=torch.bool)
    for v, b in enumerate(per_view):  # one copy per view
        dense[: len(b), v] = torch.from_numpy(b)
        has[: len(b), v] = True
    view = torch.cat([torch.full((c,), v, dtype=torch.long) for v, c in enumerate(counts)])
    index = torch.cat([torch.arange(c) for c in counts])
    return dense, has, view, index


def box_heatmaps(model, views: list, boxes: Sequence[np.ndarray], inputs: InputConfig) -> BoxHeatmaps:
    """Run ``model`` (a ``PoseNet``) once on every box of a frame; see the module docstring.

    Args:
        views: V :class:`posenet.scene.SceneView`\\ s, as ``posenet.net.inputs.build_scene`` takes them.
        boxes: V arrays ``(K_v, 4)`` xyxy pixels of those views (K_v may be 0).
    """
    if len(boxes) != len(views):
        raise ValueError(f"got {len(boxes)} box lists for {len(views)} views")
    mirrors = (False, True) if model.config.flip_test else (False,)
    if inputs.mode == "crop":
        return _crop_heatmaps(model, views, boxes, inputs, mirrors)
    dense, has, view, index = slot_layout(boxes)
    scenes: list[SceneInput] = [build_scene(views, dense, has, inputs, mirror=m) for m in mirrors]
    heats = model.heatmaps(scenes)
    K, V = has.shape
    passes = []
    for scene, heat in zip(scenes, heats, strict=True):
        box_logits = model.logits(scene, heat)[index, view]  # (N, J, M)
        M = box_logits.shape[-1]
        uv = scene.uv.to(box_logits.device).expand(K, V, M, 2)
        depth = scene.depth.to(box_logits.device).expand(K, V, M)
        valid = scene.valid.to(box_logits.device)
        box = BoxPass(box_logits, uv[index, view], depth[index, view], valid[index, view])
        if model.config.aggregation == "3d":  # the views' pixel grids, shared by the boxes of a view
            box.points = lifting.lift(scene.cameras, scene.uv, scene.depth)[0, view]  # (N, M, 3)
        passes.append(box)
    return BoxHeatmaps(view, index, scenes[0].cameras, passes, model.estimate, model.config.eps)


def _crop_heatmaps(
    model, views: list, boxes: Sequence[np.ndarray], inputs: InputConfig, mirrors
) -> BoxHeatmaps:
    """:func:`box_heatmaps` in crop mode: one crop per box (``posenet.net.inputs.build_box_crops``), every pass in
    one U-Net batch, no (slot, view) grid of empty pairs built, run or gathered."""
    crops = [build_box_crops(views, boxes, inputs, mirror=m) for m in mirrors]
    heat = model.unet_logits(crops[0].images if len(crops) == 1 else torch.cat([c.images for c in crops]))
    N = crops[0].view.shape[0]
    index = torch.cat([torch.arange(len(np.asarray(b).reshape(-1, 4))) for b in boxes])
    passes = []
    for i, c in enumerate(crops):
        logits = aug.unflip_channels(heat[i * N : (i + 1) * N], c.flipped).flatten(2)  # (N, J, M)
        dev = logits.device
        box = BoxPass(logits, c.uv.to(dev), c.depth.to(dev), c.valid.to(dev))
        if model.config.aggregation == "3d":  # each box's own crop pixels
            box.points = lifting.lift(c.cameras[c.view], box.uv[None], box.depth[None])[0]  # (N, M, 3)
        passes.append(box)
    return BoxHeatmaps(crops[0].view, index, crops[0].cameras, passes, model.estimate, model.config.eps)
