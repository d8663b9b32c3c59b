"""Training augmentation of one detector input: horizontal flip, scale jitter with a random crop, colour
jitter.

DETR from scratch sees few images here (hundreds of views), so the augmentation carries much of the
generalisation. Everything acts on a view that is already resized to the detector's input width, and on its
boxes (xyxy pixels, ``posenet.boxes``' convention), jointly.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from posenet.boxes import area_xyxy, clip_xyxy, flip_xyxy, scale_xyxy


@dataclass
class AugmentConfig:
    flip: float = 0.5  # probability of a horizontal flip (a person is a person mirrored)
    scale_min: float = (
        0.75  # scale jitter around the input size; >1 zooms in, then a random crop keeps the size
    )
    scale_max: float = 1.25
    min_visible: float = 0.3  # a box cut by the crop is kept if this fraction of its area stays in the image
    brightness: float = 0.25  # colour gains drawn from [1 - x, 1 + x]
    contrast: float = 0.25
    saturation: float = 0.25
    depth_noise_mm: float = 10.0  # Gaussian noise on valid depth


def augment_view(
    color: np.ndarray | None,
    depth: np.ndarray | None,
    boxes: np.ndarray,
    cfg: AugmentConfig,
    rng: np.random.Generator,
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
    """Augment a view: colour ``(H, W, 3)`` uint8, depth ``(H, W)`` uint16 (either may be None), boxes ``(K,
    4)``.

    Returns the augmented images, of the same size as the inputs when zooming in and smaller when zooming out
    (the batch is padded with a mask, which DETR ignores), and the surviving boxes.
    """
    ref = color if color is not None else depth
    h, w = ref.shape[:2]
    boxes = np.asarray(boxes, np.float32).reshape(-1, 4)
    if rng.random() < cfg.flip:
        color = None if color is None else np.ascontiguousarray(color[:, ::-1])
        depth = None if depth is None else np.ascontiguousarray(depth[:, ::-1])
        boxes = flip_xyxy(boxes, w)

    s = float(rng.uniform(cfg.scale_min, cfg.scale_max))
    if s != 1.0:
        size = (max(1, round(w * s)), max(1, round(h * s)))
        color = None if color is None else cv2.resize(color, size, interpolation=cv2.INTER_LINEAR)
        depth = None if depth is None else cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST)
        boxes = scale_xyxy(boxes, s)
    ref = color if color is not None else depth
    sh, sw = ref.shape[:2]
    if sw > w or sh > h:
        x0 = int(rng.integers(0, sw - w + 1)) if sw > w else 0
        y0 = int(rng.integers(0, sh - h + 1)) if sh > h else 0
        cw, ch = min(w, sw), min(h, sh)
        color = None if color is None else color[y0 : y0 + ch, x0 : x0 + cw]
        depth = None if depth is None else depth[y0 : y0 + ch, x0 : x0 + cw]
        before = area_xyxy(boxes)
        boxes = clip_xyxy(boxes - np.array([x0, y0, x0, y0], np.float32), cw, ch)
        keep = area_xyxy(boxes) >= cfg.min_visible * np.maximum(before, 1e-6)
        keep &= (boxes[:, 2] - boxes[:, 0] >= 2) & (boxes[:, 3] - boxes[:, 1] >= 2)
        boxes = boxes[keep]

    if color is not None:
        color = _jitter_color(color, cfg, rng)
    if depth is not None and cfg.depth_noise_mm > 0:
        noise = rng.normal(0.0, cfg.depth_noise_mm, depth.shape)
        depth = np.where(depth > 0, np.clip(depth + noise, 1, 65535), 0).astype(np.uint16)
    return color, depth, boxes.astype(np.float32)


def _jitter_color(color: np.ndarray, cfg: AugmentConfig, rng: np.random.Generator) -> np.ndarray:
    img = color.astype(np.float32)
    img = img * rng.uniform(1 - cfg.brightness, 1 + cfg.brightness)
    mean = img.mean()
    img = (img - mean) * rng.uniform(1 - cfg.contrast, 1 + cfg.contrast) + mean
    grey = img.mean(axis=2, keepdims=True)
    img = (img - grey) * rng.uniform(1 - cfg.saturation, 1 + cfg.saturation) + grey
    return np.clip(img, 0, 255).astype(np.uint8)
