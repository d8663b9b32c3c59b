"""Image boxes of 3D point sets, and how much of one box another covers (xyxy pixels, inclusive of the clipped
border). Their IoU is ``posenet.boxes.box_iou``."""

from __future__ import annotations

import numpy as np

from posenet.boxes import box_coverage
from posenet.rig import Rig
from posenet.synth.rig import intrinsics, world_to_cam


def project_boxes(rig: Rig, pts: np.ndarray) -> np.ndarray:
    """(V, C, 4) image-clipped xyxy boxes of point sets ``pts (C, N, 3)`` (world) in each camera."""
    T = world_to_cam(rig)
    out = []
    for v, K in enumerate(intrinsics(rig)):  # a few cameras
        pc = pts @ T[v, :3, :3].T + T[v, :3, 3]
        z = np.maximum(pc[..., 2], 50.0)
        u = K.fx * pc[..., 0] / z + K.cx
        w = K.fy * pc[..., 1] / z + K.cy
        b = np.stack([u.min(-1), w.min(-1), u.max(-1), w.max(-1)], -1)
        out.append(np.clip(b, 0, [K.width - 1, K.height - 1, K.width - 1, K.height - 1]))
    return np.stack(out)


def covered(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of box ``b``'s area covered by box ``a`` (xyxy)."""
    return float(box_coverage(a, b))
