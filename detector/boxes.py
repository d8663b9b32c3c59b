"""Box formats and the conversions between them.

Every box in this project is ``xyxy`` in pixels of its image, in ``posenet.cameras``' pixel convention: the
origin is the *centre* of the top-left pixel, so an image of width W spans ``[-0.5, W - 0.5]``. The other
formats:

- **COCO** ``[x, y, w, h]`` (MVOR's annotations and COCO results files): ``x0 = x``, ``x1 = x + w``. MVOR's
  pixel numbers are already in the camera convention (its 2D keypoints agree with its own projections there),
  so there is no half-pixel shift: the same rule as ``posenet.data.mvor``.
- **DETR** ``(cx, cy, w, h)`` normalised by the image size, with the image spanning ``[0, 1]``: ``cx = (xc +
  0.5) / W``.

Resizing an image by a factor ``f`` maps a coordinate u to ``(u + 0.5) f - 0.5`` (as ``Camera.scale``), a
horizontal flip maps it to ``W - 1 - u``. All functions take ``(..., 4)`` arrays or tensors and keep their
type (numpy in, numpy out; torch in, torch out), because they are pure arithmetic.
"""

from __future__ import annotations

import numpy as np
import torch

ArrayLike = np.ndarray | torch.Tensor


def _check(name: str, boxes: ArrayLike) -> None:
    if boxes.ndim < 1 or boxes.shape[-1] != 4:
        raise ValueError(f"{name} must have shape (..., 4), got {tuple(boxes.shape)}")


def _stack(parts: list, like: ArrayLike) -> ArrayLike:
    if isinstance(like, torch.Tensor):
        return torch.stack(parts, dim=-1)
    return np.stack(parts, axis=-1)


def coco_to_xyxy(boxes: ArrayLike) -> ArrayLike:
    """COCO ``[x, y, w, h]`` ``(..., 4)`` to xyxy pixels."""
    _check("boxes", boxes)
    x, y, w, h = (boxes[..., i] for i in range(4))
    return _stack([x, y, x + w, y + h], boxes)


def xyxy_to_coco(boxes: ArrayLike) -> ArrayLike:
    """xyxy pixels ``(..., 4)`` to COCO ``[x, y, w, h]``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack([x0, y0, x1 - x0, y1 - y0], boxes)


def xyxy_to_cxcywh_norm(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """xyxy pixels ``(..., 4)`` to DETR's normalised ``(cx, cy, w, h)`` for an image of ``width x height``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack(
        [
            ((x0 + x1) / 2 + 0.5) / width,
            ((y0 + y1) / 2 + 0.5) / height,
            (x1 - x0) / width,
            (y1 - y0) / height,
        ],
        boxes,
    )


def cxcywh_norm_to_xyxy(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """DETR's normalised ``(cx, cy, w, h)`` ``(..., 4)`` to xyxy pixels of a ``width x height`` image."""
    _check("boxes", boxes)
    cx, cy, w, h = (boxes[..., i] for i in range(4))
    cx, cy, w, h = cx * width - 0.5, cy * height - 0.5, w * width, h * height
    return _stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], boxes)


def scale_xyxy(boxes: ArrayLike, factor: float) -> ArrayLike:
    """Boxes ``(..., 4)`` of an image resized by ``factor`` (0.5 halves it)."""
    _check("boxes", boxes)
    return (boxes + 0.5) * factor - 0.5


def flip_xyxy(boxes: ArrayLike, width: int) -> ArrayLike:
    """Boxes ``(..., 4)`` of the horizontally flipped image of ``width`` pixels."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack([width - 1 - x1, y0, width - 1 - x0, y1], boxes)


def clip_xyxy(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """Boxes ``(..., 4)`` clipped to the image ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    if isinstance(boxes, torch.Tensor):
        clamp = torch.clamp
    else:
        clamp = np.clip
    return _stack(
        [
            clamp(x0, -0.5, width - 0.5),
            clamp(y0, -0.5, height - 0.5),
            clamp(x1, -0.5, width - 0.5),
            clamp(y1, -0.5, height - 0.5),
        ],
        boxes,
    )


def area_xyxy(boxes: ArrayLike) -> ArrayLike:
    """Areas ``(...)`` of boxes ``(..., 4)``; inverted boxes have area 0."""
    _check("boxes", boxes)
    w = boxes[..., 2] - boxes[..., 0]
    h = boxes[..., 3] - boxes[..., 1]
    if isinstance(boxes, torch.Tensor):
        return w.clamp_min(0) * h.clamp_min(0)
    return np.maximum(w, 0) * np.maximum(h, 0)


def iou_xyxy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise IoU ``(N, M)`` between boxes ``a (N, 4)`` and ``b (M, 4)`` (numpy, xyxy)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != 4 or b.shape[1] != 4:
        raise ValueError(f"iou_xyxy needs (N, 4) and (M, 4) boxes, got {a.shape} and {b.shape}")
    lo = np.maximum(a[:, None, :2], b[None, :, :2])  # (N, M, 2)
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])  # (N, M, 2)
    inter = np.prod(np.clip(hi - lo, 0, None), axis=-1)
    union = area_xyxy(a)[:, None] + area_xyxy(b)[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)
