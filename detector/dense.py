"""A training-only dense loss on DETR's encoder tokens, to speed up training from scratch.

DETR trained from random weights learns slowly: its only signal is the set loss of a few queries, and the
encoder's tokens get no direct supervision, so the decoder's queries have nothing distinctive to attend to for
thousands of steps (the class loss sits at its prior; docs/detector.md). This module adds a dense signal in the
style of one-stage detectors (FCOS, CenterNet) and of the encoder proposals of two-stage Deformable DETR: every
encoder token near a person's box centre must say "person" (sigmoid focal loss) and regress that box (L1 +
GIoU, DETR's weights). The heads are two small layers beside the model; they are not part of
``DetrForObjectDetection``, are never used at inference, and the detector that ships is an unchanged DETR.

The token grid is read from the backbone's output by a forward hook, so any input size and backbone stride
works; the encoder flattens the grid row-major (token ``i * w + j``).
"""

from __future__ import annotations

import torch
from torch import nn
from torchvision.ops import box_convert, generalized_box_iou_loss, sigmoid_focal_loss


class DenseHead(nn.Module):
    """Objectness logit and a box (normalised cx, cy, w, h) for every encoder token."""

    def __init__(self, d_model: int) -> None:
        super().__init__()
        self.objectness = nn.Linear(d_model, 1)
        self.box = nn.Sequential(nn.Linear(d_model, d_model), nn.ReLU(), nn.Linear(d_model, 4))
        nn.init.constant_(
            self.objectness.bias, -4.6
        )  # prior 0.01, as in RetinaNet: most tokens are background
        nn.init.zeros_(self.box[-1].weight)
        nn.init.zeros_(self.box[-1].bias)

    def forward(self, tokens: torch.Tensor, centres: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``tokens`` (B, N, d) and token ``centres`` (B, N, 2) normalised -> logits (B, N), boxes (B, N, 4).

        Box centres are offsets from the token's own centre (in logit space), sizes start at 0.1 of the image.
        """
        delta = self.box(tokens)
        centre = torch.special.logit(centres.clamp(1e-4, 1 - 1e-4)) + delta[..., :2]
        size = delta[..., 2:] - 2.2  # sigmoid(-2.2) ~ 0.1
        return self.objectness(tokens)[..., 0], torch.sigmoid(torch.cat([centre, size], dim=-1))


def token_centres(pixel_mask: torch.Tensor, grid: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised (x, y) of each token's centre in its own (unpadded) image (B, h*w, 2), and the token
    stride in the same units (B, 2).

    DETR's boxes are normalised by the unpadded image size; ``pixel_mask`` (B, H, W) gives that size.
    """
    b, height, width = pixel_mask.shape
    h, w = grid
    stride_y, stride_x = height / h, width / w
    ys = (torch.arange(h, dtype=torch.float32) + 0.5) * stride_y
    xs = (torch.arange(w, dtype=torch.float32) + 0.5) * stride_x
    valid_w = pixel_mask[:, 0, :].sum(-1).clamp(min=1).float()  # padding is at the right and bottom
    valid_h = pixel_mask[:, :, 0].sum(-1).clamp(min=1).float()
    cx = xs[None, None, :].expand(b, h, w) / valid_w[:, None, None]
    cy = ys[None, :, None].expand(b, h, w) / valid_h[:, None, None]
    stride = torch.stack([stride_x / valid_w, stride_y / valid_h], dim=-1)
    return torch.stack([cx, cy], dim=-1).reshape(b, h * w, 2), stride


def dense_targets(
    labels: list[dict], centres: torch.Tensor, strides: torch.Tensor, radius: float = 1.5
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per token: 1 where it is positive for a box, and that box (B, N, 4) (zeros elsewhere).

    A token is positive for a box when its centre lies inside the box and within ``radius`` token strides of
    the box centre (FCOS's centre sampling); the token nearest the centre always is, so tiny boxes get one.
    A token positive for several boxes takes the smallest.
    """
    b, n, _ = centres.shape
    target = torch.zeros(b, n)
    boxes = torch.zeros(b, n, 4)
    for i, lab in enumerate(labels):
        gt = lab["boxes"].float()  # (K, 4) normalised cx, cy, w, h
        if len(gt) == 0:
            continue
        c = centres[i]  # (N, 2)
        stride = strides[i]
        d = (c[:, None, :] - gt[None, :, :2]).abs()  # (N, K, 2)
        inside = (d <= gt[None, :, 2:] / 2).all(-1)
        near = (d <= radius * stride).all(-1)
        pos = inside & near
        nearest = (d / stride).pow(2).sum(-1).argmin(0)  # (K,)
        pos[nearest, torch.arange(len(gt))] = True
        area = (gt[:, 2] * gt[:, 3])[None, :].expand(n, -1)
        area = torch.where(pos, area, torch.full_like(area, float("inf")))
        best = area.argmin(1)
        hit = pos.any(1)
        target[i, hit] = 1.0
        boxes[i, hit] = gt[best[hit]]
    return target, boxes


class DenseLoss(nn.Module):
    """The dense loss of one forward pass; ``attach(model)`` hooks the backbone to learn the token grid."""

    def __init__(
        self, d_model: int, focal_weight: float = 2.0, l1_weight: float = 5.0, giou_weight: float = 2.0
    ):
        super().__init__()
        self.head = DenseHead(d_model)
        self.weights = (focal_weight, l1_weight, giou_weight)
        self._grid: tuple[int, int] | None = None

    def attach(self, model: nn.Module) -> None:
        """Record the backbone's output grid (h, w) on every forward pass of ``model`` (a DETR)."""

        def hook(_module, _inputs, output):
            self._grid = tuple(output[-1][0].shape[-2:])

        model.model.backbone.register_forward_hook(hook)

    def forward(self, encoder_tokens: torch.Tensor, pixel_mask: torch.Tensor, labels: list[dict]) -> dict:
        """``{"loss_dense": weighted sum, "dense_focal", "dense_l1", "dense_giou"}`` for one batch."""
        if self._grid is None:
            raise RuntimeError("DenseLoss.attach(model) must run before the model's forward pass")
        centres, strides = token_centres(pixel_mask, self._grid)
        logits, pred = self.head(encoder_tokens, centres)
        target, boxes = dense_targets(labels, centres, strides)
        n_pos = target.sum().clamp(min=1.0)
        focal = sigmoid_focal_loss(logits, target, alpha=0.25, gamma=2.0, reduction="sum") / n_pos
        pos = target > 0
        if pos.any():
            l1 = (pred[pos] - boxes[pos]).abs().sum() / n_pos
            giou = (
                generalized_box_iou_loss(
                    box_convert(pred[pos], "cxcywh", "xyxy"),
                    box_convert(boxes[pos], "cxcywh", "xyxy"),
                    reduction="sum",
                )
                / n_pos
            )
        else:
            l1 = giou = logits.sum() * 0.0
        wf, wl, wg = self.weights
        return {
            "loss_dense": wf * focal + wl * l1 + wg * giou,
            "dense_focal": focal.detach(),
            "dense_l1": l1.detach(),
            "dense_giou": giou.detach(),
        }
