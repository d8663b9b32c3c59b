"""Image preprocessing of the detector: the one place that turns views into DETR's ``pixel_values``.

Training, prediction and the service all go through these functions, driven by the ``DetectorConfig`` saved
with each checkpoint, so preprocessing can never drift between them. A view is resized to ``cfg.input_width``
(aspect kept; colour with ``INTER_AREA``, depth with nearest neighbour so that no depth is invented between a
person and the wall behind), then normalised: colour with ImageNet statistics, depth as ``(mm - mean) / std``
with unknown depth (0) kept at 0 after normalisation, i.e. "average depth", plus no false edge.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import torch

from detector.model import DetectorConfig


def resize_factor(width: int, cfg: DetectorConfig) -> float:
    """The factor that maps an image of ``width`` pixels to the detector's input width."""
    return cfg.input_width / float(width)


def resize_view(
    color: np.ndarray | None, depth: np.ndarray | None, factor: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Resize a colour ``(H, W, 3)`` uint8 and/or depth ``(H, W)`` uint16 image by ``factor``."""
    out = []
    for img, interp in (
        (color, cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR),
        (depth, cv2.INTER_NEAREST),
    ):
        if img is None or factor == 1.0:
            out.append(img)
            continue
        h, w = img.shape[:2]
        size = (max(1, round(w * factor)), max(1, round(h * factor)))
        out.append(cv2.resize(img, size, interpolation=interp))
    return out[0], out[1]


def normalise(color: np.ndarray | None, depth: np.ndarray | None, cfg: DetectorConfig) -> torch.Tensor:
    """One view's ``(C, H, W)`` float32 input for ``cfg.input_mode`` from colour ``(H, W, 3)`` / depth ``(H,
    W)``."""
    channels = []
    if cfg.input_mode in ("rgb", "rgbd"):
        if color is None or color.ndim != 3 or color.shape[2] != 3:
            shape = None if color is None else color.shape
            raise ValueError(
                f"input_mode {cfg.input_mode!r} needs an (H, W, 3) uint8 colour image, got {shape}"
            )
        rgb = torch.from_numpy(np.ascontiguousarray(color)).permute(2, 0, 1).float() / 255.0  # (3, H, W)
        mean = torch.tensor(cfg.rgb_mean).view(3, 1, 1)
        std = torch.tensor(cfg.rgb_std).view(3, 1, 1)
        channels.append((rgb - mean) / std)
    if cfg.input_mode in ("depth", "rgbd"):
        if depth is None or depth.ndim != 2:
            shape = None if depth is None else depth.shape
            raise ValueError(f"input_mode {cfg.input_mode!r} needs an (H, W) uint16 depth image, got {shape}")
        d = torch.from_numpy(depth.astype(np.float32))
        d = torch.where(d > 0, (d - cfg.depth_mean_mm) / cfg.depth_std_mm, torch.zeros_like(d))
        channels.append(d[None])  # (1, H, W)
    if len(channels) == 2 and channels[0].shape[1:] != channels[1].shape[1:]:
        raise ValueError(
            f"colour {tuple(channels[0].shape[1:])} and depth {tuple(channels[1].shape[1:])} differ"
        )
    return torch.cat(channels, dim=0)


def _round_up(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


def box_frame(width: int, height: int, cfg: DetectorConfig) -> tuple[int, int]:
    """The (width, height) that a ``width`` x ``height`` view's normalised boxes refer to: the view itself for
    DETR, the view padded to ``cfg.pad_multiple`` for RT-DETR (whose anchors span the padded grid)."""
    return _round_up(width, cfg.pad_multiple), _round_up(height, cfg.pad_multiple)


def batch_inputs(tensors: Sequence[torch.Tensor], multiple: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """Pad ``(C, H_i, W_i)`` inputs at the bottom/right into ``pixel_values (B, C, H, W)`` and ``pixel_mask
    (B, H, W)``; ``H`` and ``W`` are rounded up to ``multiple``.

    The mask is 1 on real pixels: DETR's positional encoding and attention then ignore the padding.
    """
    if not tensors:
        raise ValueError("batch_inputs needs at least one image")
    c = tensors[0].shape[0]
    h = _round_up(max(t.shape[1] for t in tensors), multiple)
    w = _round_up(max(t.shape[2] for t in tensors), multiple)
    pixels = tensors[0].new_zeros((len(tensors), c, h, w))
    mask = torch.zeros((len(tensors), h, w), dtype=torch.long)
    for i, t in enumerate(tensors):
        pixels[i, :, : t.shape[1], : t.shape[2]] = t
        mask[i, : t.shape[1], : t.shape[2]] = 1
    return pixels, mask


def prepare_views(
    colors: Sequence[np.ndarray | None], depths: Sequence[np.ndarray | None], cfg: DetectorConfig
) -> tuple[torch.Tensor, torch.Tensor, list[float], list[tuple[int, int]]]:
    """Full-size views to one padded batch.

    Returns ``pixel_values (B, C, H, W)``, ``pixel_mask (B, H, W)``, the resize factor of each view and the
    ``(width, height)`` that each view's normalised boxes refer to (``box_frame``: the resized view, padded for
    RT-DETR).
    """
    if len(colors) != len(depths):
        raise ValueError(f"got {len(colors)} colour images but {len(depths)} depth images")
    tensors, factors, sizes = [], [], []
    for color, depth in zip(colors, depths, strict=True):
        ref = color if color is not None else depth
        if ref is None:
            raise ValueError("a view needs a colour or a depth image")
        factor = resize_factor(ref.shape[1], cfg)
        use_color = color if cfg.input_mode in ("rgb", "rgbd") else None
        use_depth = depth if cfg.input_mode in ("depth", "rgbd") else None
        c, d = resize_view(use_color, use_depth, factor)
        t = normalise(c, d, cfg)
        tensors.append(t)
        factors.append(factor)
        sizes.append(box_frame(t.shape[2], t.shape[1], cfg))
    pixels, mask = batch_inputs(tensors, cfg.pad_multiple)
    return pixels, mask, factors, sizes
