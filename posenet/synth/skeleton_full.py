"""The renderer's full-body skeleton: MVOR's 12 annotated points plus knees, ankles and toes.

The first 12 points are exactly MVOR's ``keypoints3D`` order (the 10 joints of ``posenet.skeleton`` and the
two hand points about 9 cm beyond the wrists), so a rendered body's annotation is ``points[:12]``. Segment
lengths are MVOR's medians (measured on ``camma_mvor_2018.json``, whose shoulders, elbows and wrists sit
inside the body, so its arms are shorter than textbook anthropometry) for a person of :data:`REF_STATURE`;
the legs, which MVOR does not annotate, follow Winter's anthropometric table (hip 0.530, knee 0.285, ankle
0.039 of stature).
"""

from __future__ import annotations

import numpy as np

from posenet.skeleton import JOINTS

# MVOR's 10 joints, then its two hand points, then the legs that MVOR does not annotate.
FULL_JOINTS: tuple[str, ...] = JOINTS + (
    "left_hand",
    "right_hand",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
    "left_toe",
    "right_toe",
)
NUM_FULL = len(FULL_JOINTS)
F = {name: i for i, name in enumerate(FULL_JOINTS)}
NUM_MVOR_POINTS = 12  # the annotated prefix

REF_STATURE = 1720.0  # mm, the stature the lengths below describe
LENGTHS = {  # mm at REF_STATURE
    "head_neck": 116.0,  # MVOR
    "shoulder_width": 337.0,  # MVOR, joint to joint
    "hip_width": 319.0,  # MVOR
    "trunk": 411.0,  # MVOR shoulder to hip
    "neck_above_shoulders": 88.0,  # from MVOR's neck-shoulder 190 and half shoulder width
    "upper_arm": 250.0,  # MVOR
    "forearm": 188.0,  # MVOR
    "hand": 87.0,  # MVOR
    "thigh": 0.245 * REF_STATURE,  # Winter: hip 0.530 - knee 0.285
    "shin": 0.246 * REF_STATURE,  # Winter: knee 0.285 - ankle 0.039
    "ankle_height": 0.039 * REF_STATURE,
    "foot": 0.11 * REF_STATURE,  # ankle to toe tip, horizontal
}

UP = np.array([0.0, 0.0, 1.0])  # world "up": the renderer's room frame has z up, floor at z = 0


def unit(v: np.ndarray) -> np.ndarray:
    """Normalise along the last axis."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues rotation of vectors ``v (..., 3)`` about a unit ``axis (3,)`` by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * (v @ axis)[..., None] * (1 - c)


def body_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The trunk's (forward, left, up) unit axes from a full skeleton ``(NUM_FULL or 12, 3)``."""
    mid_hip = (points[F["left_hip"]] + points[F["right_hip"]]) / 2
    up = unit(points[F["neck"]] - mid_hip)
    lat = points[F["left_shoulder"]] - points[F["right_shoulder"]]
    lat = lat + (points[F["left_hip"]] - points[F["right_hip"]])
    left = unit(lat - up * (lat @ up))
    fwd = np.cross(left, up)
    return fwd, left, up


def complete_legs(points12: np.ndarray, floor_z: float = 0.0) -> np.ndarray:
    """Full skeleton ``(NUM_FULL, 3)`` from MVOR's 12 points ``(12, 3)`` in a z-up frame with the floor at
    ``floor_z``.

    The ankles go straight below the hips (slightly forward and outward), at ankle height above the floor;
    the knees follow by two-link inverse kinematics, bending forward. Leg lengths scale with the trunk; legs
    too short for the floor are stretched by at most 15 %, then the feet hover.
    """
    if points12.shape != (NUM_MVOR_POINTS, 3):
        raise ValueError(f"points12 must have shape (12, 3), got {points12.shape}")
    p = np.zeros((NUM_FULL, 3))
    p[:NUM_MVOR_POINTS] = points12
    mid_sh = (points12[2] + points12[3]) / 2
    mid_hip = (points12[4] + points12[5]) / 2
    scale = float(np.clip(np.linalg.norm(mid_sh - mid_hip) / LENGTHS["trunk"], 0.8, 1.25))
    hip_dir = points12[4] - points12[5]
    hip_dir[2] = 0
    fwd = np.cross(unit(hip_dir), UP) if np.linalg.norm(hip_dir) > 1 else np.array([1.0, 0, 0])
    fwd = unit(fwd)
    l1, l2 = LENGTHS["thigh"] * scale, LENGTHS["shin"] * scale
    ankle_z = floor_z + LENGTHS["ankle_height"] * scale
    for side, (hip, knee, ankle, toe) in enumerate(((4, 12, 14, 16), (5, 13, 15, 17))):
        out = unit(hip_dir) * (1 if side == 0 else -1)
        H = points12[hip]
        A = np.array([H[0], H[1], ankle_z]) + fwd * 30 * scale + out * 25 * scale
        D = np.linalg.norm(H - A)
        stretch = float(np.clip(D / (l1 + l2), 1.0, 1.15))
        a1, a2 = l1 * stretch, l2 * stretch
        u = unit(A - H)
        if D >= a1 + a2:
            A = H + u * (a1 + a2) * 0.999
            D = (a1 + a2) * 0.999
        a = (a1 * a1 - a2 * a2 + D * D) / (2 * D)
        h = np.sqrt(max(a1 * a1 - a * a, 0.0))
        perp = unit(fwd - u * (fwd @ u))
        p[knee] = H + u * a + perp * h
        p[ankle] = A
        p[toe] = A + fwd * LENGTHS["foot"] * scale + out * 20 * scale - UP * (A[2] - floor_z - 25 * scale)
    return p


def estimate_floor(poses_up: np.ndarray) -> float:
    """Floor height (mm, along z) from many MVOR poses ``(N, 12, 3)`` expressed in a z-up frame.

    Uses people whose trunk is within 20 degrees of vertical: their hips stand about a straight leg
    (thigh + shin + ankle height, scaled by the trunk) above the floor, less 2 % for relaxed knees.
    """
    mid_sh = (poses_up[:, 2] + poses_up[:, 3]) / 2
    mid_hip = (poses_up[:, 4] + poses_up[:, 5]) / 2
    trunk = mid_sh - mid_hip
    scale = np.clip(np.linalg.norm(trunk, axis=1) / LENGTHS["trunk"], 0.8, 1.25)
    upright = unit(trunk)[:, 2] > np.cos(np.radians(20))
    if upright.sum() < 3:
        raise ValueError(f"need at least 3 upright poses to find the floor, got {int(upright.sum())}")
    leg = (LENGTHS["thigh"] + LENGTHS["shin"] + LENGTHS["ankle_height"]) * scale * 0.98
    return float(np.median(mid_hip[upright, 2] - leg[upright]))
