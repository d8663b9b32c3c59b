"""The ``alt`` look's body model: another team's idea of a person, for the unseen-look test set.

Where the twin body (:mod:`posenet.synth.body`) is tapered round cones and stacked ellipsoids built on the
annotated points, this one is built like a quick game-engine mannequin: untapered capsules for the limbs, a trunk
of three horizontal capsules (shoulder line, chest, waist) over a pelvis capsule, a near-spherical head centred
close to MVOR's head point, mitten hands, box shoes, a coat as a cone and a lead apron as a flat slab. Its
anatomical joints sit elsewhere inside the flesh (:data:`ALT_OFFSETS`: shoulders higher and wider, hips lower),
outside the ranges that the ``random`` look draws (:mod:`posenet.synth.looks`). Nothing trains on it.
"""

from __future__ import annotations

import numpy as np

from posenet.synth.body import BodyShape, Outfit, flesh_skeleton
from posenet.synth.primitives import Primitive, box, capsule, ellipsoid, round_cone
from posenet.synth.skeleton_full import LENGTHS, NUM_FULL, F, unit


def _offsets() -> np.ndarray:
    o = np.zeros((NUM_FULL, 3))  # forward, outward, up (mm)
    o[F["neck"]] = (-15.0, 0.0, -25.0)
    for side in ("left", "right"):
        o[F[f"{side}_shoulder"]] = (-25.0, 30.0, 50.0)  # random draws up 0..35, outward -10..20
        o[F[f"{side}_hip"]] = (10.0, 25.0, -95.0)  # random draws down 0..70
        o[F[f"{side}_elbow"]] = (-20.0, 10.0, 0.0)
        o[F[f"{side}_wrist"]] = (0.0, 0.0, -15.0)
    return o


ALT_OFFSETS = _offsets()
ALT_SHAPE = BodyShape(offsets=ALT_OFFSETS, model="alt")


def alt_body_primitives(points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape) -> list[Primitive]:
    """Primitives of one person from a full skeleton ``(NUM_FULL, 3)`` (z-up world frame, mm)."""
    (fwd, left, up), P, mid_sh, mid_hip, spine = flesh_skeleton(points, shape.offsets)
    trunk = float(np.linalg.norm(spine))
    s = float(
        np.clip(trunk / (LENGTHS["trunk"] + 145.0), 0.8, 1.25)
    )  # its trunk is the longer anatomical one
    k = s * outfit.bulk
    out: list[Primitive] = []

    def cap_(a, b, r, mat):
        out.append(capsule(a, b, r, owner, mat))

    # Head: a near-sphere just behind the face point; a flat cap on top, a thin mask in front.
    hd = unit(P["head"] - P["neck"])
    hf = unit(fwd - hd * (fwd @ hd))
    hl = np.cross(hd, hf)
    head_c = P["head"] + hd * 25 * s - hf * 45 * s
    axes = np.stack([hl, hf, hd], 1)
    out.append(ellipsoid(head_c, np.array([92, 100, 104]) * s, axes, owner, outfit.skin))
    if outfit.cap is not None:
        out.append(ellipsoid(head_c + hd * 50 * s, np.array([100, 108, 62]) * s, axes, owner, outfit.cap))
    elif outfit.hair is not None:
        out.append(ellipsoid(head_c + hd * 20 * s - hf * 10 * s, np.array([96, 102, 96]) * s, axes, owner,
                             outfit.hair))  # fmt: skip
    if outfit.mask is not None:
        out.append(ellipsoid(head_c + hf * 88 * s - hd * 28 * s, np.array([66, 22, 44]) * s, axes, owner,
                             outfit.mask))  # fmt: skip
    cap_(P["neck"] - up * 40 * s, head_c - hd * 60 * s, 56 * s, outfit.skin)
    # Trunk: horizontal capsules; they end inside the shoulders and hips, so the sides are round.
    sh_half = float(np.linalg.norm(P["left_shoulder"] - P["right_shoulder"])) / 2
    hip_half = float(np.linalg.norm(P["left_hip"] - P["right_hip"])) / 2
    for at, half, r in ((0.93, sh_half - 30 * s, 68 * k), (0.62, sh_half - 50 * s, 116 * k),
                        (0.28, hip_half - 20 * s, 106 * k)):  # fmt: skip
        c = mid_hip + spine * at
        cap_(c + left * half, c - left * half, r, outfit.top)
    cap_(P["left_hip"] + up * 40 * s, P["right_hip"] + up * 40 * s, 98 * k, outfit.trousers)
    if outfit.apron is not None:
        R = np.stack([left, fwd, up], 1)
        c = mid_hip + spine * 0.42 + fwd * 120 * k
        out.append(box(c, [sh_half + 40 * k, 14.0, 0.62 * trunk], R, owner, outfit.apron))
    # Limbs: one radius from joint to joint.
    for side in ("left", "right"):
        cap_(P[f"{side}_shoulder"], P[f"{side}_elbow"], 47 * k, outfit.top)
        cap_(P[f"{side}_elbow"], P[f"{side}_wrist"], 35 * k, outfit.top if outfit.gown else outfit.skin)
        hand_dir = unit(P[f"{side}_hand"] - P[f"{side}_wrist"])
        out.append(ellipsoid(P[f"{side}_hand"] - hand_dir * 20 * s, np.array([44, 44, 44]) * s, None, owner,
                             outfit.hands))  # fmt: skip
        cap_(P[f"{side}_hip"], P[f"{side}_knee"], 72 * k, outfit.trousers)
        cap_(P[f"{side}_knee"], P[f"{side}_ankle"], 50 * k, outfit.trousers)
        toe = P[f"{side}_toe"]
        ankle = P[f"{side}_ankle"] - up * 40 * s
        f = unit((toe - ankle) - up * ((toe - ankle) @ up))
        R = np.stack([f, np.cross(up, f), up], 1)
        half_len = float(np.linalg.norm(toe - ankle)) / 2 + 20 * s
        out.append(box((toe + ankle) / 2 - up * 5 * s, [half_len, 48 * s, 38 * s], R, owner, outfit.shoes))
    if outfit.gown:  # a coat: a cone from the waist to below the knees
        knees = (P["left_knee"] + P["right_knee"]) / 2
        lo = knees - unit(mid_hip - knees) * 90 * s
        ra, rb = hip_half + 95 * k, hip_half + 130 * k
        if np.linalg.norm(mid_hip - lo) > abs(ra - rb) + 1:
            out.append(round_cone(mid_hip + up * 60 * s, lo, ra, rb, owner, outfit.top))
    return out
