"""Image boxes of 3D point sets, and box overlap measures (xyxy pixels, inclusive of the clipped border)."""

from __future__ import annotations

import numpy as np

from posenet.data.synth.rig import Rig


def project_boxes(rig: Rig, pts: np.ndarray) -> np.ndarray:
    """(V, C, 4) image-clipped xyxy boxes of point sets ``pts (C, N, 3)`` (world) in each camera."""
    T = rig.world_to_cam()
    out = []
    for v, K in enumerate(rig.intrinsics):  # a few cameras
        pc = pts @ T[v, :3, :3].T + T[v, :3, 3]
        z = np.maximum(pc[..., 2], 50.0)
        u = K.fx * pc[..., 0] / z + K.cx
        w = K.fy * pc[..., 1] / z + K.cy
        b = np.stack([u.min(-1), w.min(-1), u.max(-1), w.max(-1)], -1)
        out.append(np.clip(b, 0, [K.width - 1, K.height - 1, K.width - 1, K.height - 1]))
    return np.stack(out)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of xyxy boxes ``a (..., 4)`` and ``b (..., 4)`` (broadcast)."""
    iw = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    ih = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = iw * ih
    area = lambda x: (x[..., 2] - x[..., 0]) * (x[..., 3] - x[..., 1])  # noqa: E731
    return inter / np.maximum(area(a) + area(b) - inter, 1e-9)


def covered(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of box ``b``'s area covered by box ``a`` (xyxy)."""
    iw = max(min(a[2], b[2]) - max(a[0], b[0]), 0)
    ih = max(min(a[3], b[3]) - max(a[1], b[1]), 0)
    return float(iw * ih / max((b[2] - b[0]) * (b[3] - b[1]), 1e-9))
