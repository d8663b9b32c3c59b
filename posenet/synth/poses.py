"""Procedural poses: a sampler over joint angles for the postures seen around an operating table.

A pose is built by forward kinematics in the person's own frame (x forward, y left, z up, feet on the floor at
z = 0), then turned by a yaw and moved to a floor position. Postures: standing, bending over the table,
reaching, arms raised, arms crossed, turning; every angle is drawn inside a natural range. Lengths come from
:mod:`posenet.synth.skeleton_full` scaled by the stature; the patient's lying pose is also here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posenet.synth.skeleton_full import LENGTHS, NUM_FULL, REF_STATURE, F, rotate, unit

POSTURES = ("standing", "bending", "reaching", "arms_raised", "arms_crossed", "turning")
POSTURE_WEIGHTS = (0.25, 0.25, 0.18, 0.08, 0.10, 0.14)

X, Y, Z = np.eye(3)


@dataclass
class PoseParams:
    """Joint angles in radians (flexion forward is positive), lengths in mm."""

    stature: float = REF_STATURE
    trunk_pitch: float = 0.0  # bending forward at the hips
    trunk_roll: float = 0.0  # leaning sideways
    twist: float = 0.0  # shoulders turned against the pelvis, about the spine
    head_pitch: float = 0.2  # looking down
    head_yaw: float = 0.0
    shoulder_flex: tuple[float, float] = (0.1, 0.1)  # (left, right), arm raised forward
    shoulder_abd: tuple[float, float] = (0.1, 0.1)  # arm raised sideways (negative: across the chest)
    elbow_flex: tuple[float, float] = (0.3, 0.3)
    forearm_in: tuple[float, float] = (0.3, 0.3)  # how much the bending forearm swings toward the midline
    hip_flex: tuple[float, float] = (0.0, 0.0)
    knee_flex: tuple[float, float] = (0.05, 0.05)
    stance: float = 120.0  # extra distance between the feet


def sample_params(rng: np.random.Generator, posture: str | None = None) -> tuple[str, PoseParams]:
    """Draw a posture (by :data:`POSTURE_WEIGHTS` unless given) and its angles."""
    if posture is None:
        posture = str(rng.choice(POSTURES, p=POSTURE_WEIGHTS))
    if posture not in POSTURES:
        raise ValueError(f"unknown posture {posture!r}; expected one of {POSTURES}")
    u = rng.uniform

    def pair(lo, hi, spread=0.3):  # left/right angles, correlated
        base = u(lo, hi)
        return tuple(float(np.clip(base + rng.normal(0, spread), lo, hi)) for _ in range(2))

    p = PoseParams(
        stature=float(np.clip(rng.normal(1720, 80), 1540, 1960)),
        trunk_pitch=u(-0.05, 0.25),
        trunk_roll=rng.normal(0, 0.05),
        twist=rng.normal(0, 0.12),
        head_pitch=u(-0.1, 0.6),
        head_yaw=rng.normal(0, 0.3),
        shoulder_flex=pair(-0.2, 0.6),
        shoulder_abd=pair(0.0, 0.35, 0.1),
        elbow_flex=pair(0.1, 1.6),
        forearm_in=pair(0.0, 0.8),
        hip_flex=pair(-0.05, 0.15, 0.1),
        knee_flex=pair(0.0, 0.25, 0.1),
        stance=u(60, 300),
    )
    if posture == "bending":
        p.trunk_pitch = u(0.35, 1.1)
        p.head_pitch = u(0.2, 0.8)
        p.shoulder_flex = pair(0.6, 1.4)
        p.elbow_flex = pair(0.4, 1.8)
        p.knee_flex = pair(0.0, 0.35, 0.1)
    elif posture == "reaching":
        p.trunk_pitch = u(0.1, 0.6)
        flex = (u(0.9, 1.8), u(-0.2, 1.6))
        p.shoulder_flex = flex if rng.random() < 0.5 else flex[::-1]
        p.elbow_flex = pair(0.0, 0.6)
        p.shoulder_abd = pair(-0.2, 0.6, 0.2)
    elif posture == "arms_raised":
        p.shoulder_flex = pair(1.9, 2.8, 0.2)
        p.shoulder_abd = pair(0.1, 0.6, 0.2)
        p.elbow_flex = pair(0.0, 1.4)
        p.head_pitch = u(-0.3, 0.2)
    elif posture == "arms_crossed":
        p.shoulder_flex = pair(0.2, 0.6, 0.1)
        p.shoulder_abd = pair(-0.45, -0.2, 0.05)
        p.elbow_flex = pair(1.7, 2.2, 0.1)
        p.forearm_in = pair(1.2, 1.5, 0.1)
    elif posture == "turning":
        p.twist = float(rng.choice([-1, 1]) * u(0.4, 0.8))
        p.head_yaw = p.twist * u(0.5, 1.2)
    return posture, p


def build_pose(p: PoseParams) -> np.ndarray:
    """Full skeleton ``(NUM_FULL, 3)`` in the person's frame (x forward, y left, z up, floor at z = 0)."""
    s = p.stature / REF_STATURE
    L = {k: v * s for k, v in LENGTHS.items()}
    pts = np.zeros((NUM_FULL, 3))
    hips = [np.array([0.0, L["hip_width"] / 2, 0.0]), np.array([0.0, -L["hip_width"] / 2, 0.0])]
    for i, side in enumerate((1, -1)):
        thigh = rotate(-Z, Y, -p.hip_flex[i])  # flexion swings the thigh forward (+x)
        thigh = rotate(thigh, X, side * 0.04 + side * p.stance / 4000)
        shin = rotate(thigh, Y, p.knee_flex[i])  # the knee bends the shin backward
        knee = hips[i] + thigh * L["thigh"]
        ankle = knee + shin * L["shin"]
        pts[F["left_hip"] + i] = hips[i]
        pts[F["left_knee"] + i] = knee
        pts[F["left_ankle"] + i] = ankle
        toe_dir = unit(np.array([1.0, side * 0.25, 0.0]))
        pts[F["left_toe"] + i] = ankle + toe_dir * L["foot"] - Z * (L["ankle_height"] - 25 * s)
    # Trunk: pitch forward about the hip axis, then roll sideways.
    spine = rotate(rotate(Z, Y, p.trunk_pitch), X, p.trunk_roll)
    left = rotate(rotate(Y, Y, p.trunk_pitch), X, p.trunk_roll)
    left = rotate(left, spine, p.twist)
    fwd = np.cross(left, spine)
    mid_sh = spine * L["trunk"]
    pts[F["left_shoulder"]] = mid_sh + left * L["shoulder_width"] / 2
    pts[F["right_shoulder"]] = mid_sh - left * L["shoulder_width"] / 2
    neck = mid_sh + spine * L["neck_above_shoulders"]
    pts[F["neck"]] = neck
    head_dir = rotate(rotate(spine, left, p.head_pitch), spine, p.head_yaw)
    pts[F["head"]] = neck + head_dir * L["head_neck"]
    for i, side in enumerate((1, -1)):
        sh = pts[F["left_shoulder"] + i]
        upper = rotate(-spine, left, -p.shoulder_flex[i])  # flexion raises the arm forward
        upper = rotate(upper, fwd, -side * p.shoulder_abd[i])  # abduction raises it sideways
        toward = unit(fwd * np.cos(p.forearm_in[i]) - left * side * np.sin(p.forearm_in[i]) + spine * 0.2)
        axis = np.cross(upper, toward)
        if np.linalg.norm(axis) < 1e-3:  # forearm target along the upper arm: bend upward instead
            axis = np.cross(upper, spine)
        fore = rotate(upper, unit(axis), p.elbow_flex[i])
        elbow = sh + upper * L["upper_arm"]
        wrist = elbow + fore * L["forearm"]
        pts[F["left_elbow"] + i] = elbow
        pts[F["left_wrist"] + i] = wrist
        pts[F["left_hand"] + i] = wrist + fore * L["hand"]
    # Hips sit at the origin so far: lift everything so that the lowest toe or ankle touches the floor.
    ground = min(pts[F["left_ankle"], 2], pts[F["right_ankle"], 2]) - L["ankle_height"]
    pts[:, 2] -= ground
    return pts


def place(pts: np.ndarray, xy: np.ndarray, yaw: float, floor_z: float = 0.0) -> np.ndarray:
    """Turn a body-frame skeleton ``(N, 3)`` by ``yaw`` about z and put it at floor position ``xy``."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    mid = (pts[F["left_hip"]] + pts[F["right_hip"]]) / 2
    out = (pts - [mid[0], mid[1], 0]) @ R.T
    return out + [xy[0], xy[1], floor_z]


def lying_pose(rng: np.random.Generator, stature: float | None = None) -> np.ndarray:
    """A patient lying on the back along +x, head toward -x, hips at the origin ``(NUM_FULL, 3)``, body
    frame z up."""
    st = stature if stature is not None else float(np.clip(rng.normal(1700, 90), 1500, 1950))
    p = PoseParams(
        stature=st,
        shoulder_flex=(rng.uniform(-0.1, 0.3), rng.uniform(-0.1, 0.3)),
        shoulder_abd=(rng.uniform(0.05, 0.4), rng.uniform(0.05, 0.4)),
        elbow_flex=(rng.uniform(0, 0.6), rng.uniform(0, 0.6)),
        head_pitch=0.0,
        head_yaw=0.0,
        knee_flex=(0.1, 0.1),
        stance=40.0,
    )
    pts = build_pose(p)
    mid = (pts[F["left_hip"]] + pts[F["right_hip"]]) / 2
    pts = pts - mid
    # Standing (z up, facing +x) to lying on the back: rotate -90 degrees about y, so the head points to -x.
    R = np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]])
    return pts @ R.T
