"""A body grammar for the ``random`` look: each person's flesh built from primitives of drawn kinds.

The twin body (:mod:`posenet.synth.body`) is one construction (an ellipsoid trunk, tapered limbs, a head
centred beyond the face point) whose sizes the ``random`` look varies. Renderers and real people differ more than
in size: in how a trunk is shaped, whether limbs taper, where the skull sits around the annotated head point. The
look-factor benchmark (``benchmarks/look_factors.py``) found the body to be most of the unseen look's cost (88 %
of it with the shipped weights of 2026-12-02), so half of the ``random`` look's people are built by this grammar
instead, from their own seed (``BodyShape.grammar``), the same body in every frame of a sequence:

- head: an ellipsoid (or, 15 %, a box) of 75-100 / 85-110 / 95-125 mm half axes whose centre lies -10..60 mm
  beyond the head point along the neck and 0..70 mm behind it, so the head point is anywhere from the face to
  the skull's middle; a neck of 38-65 mm;
- trunk: a stack of 2-4 horizontal ellipsoids, capsules or boxes (one kind per person) from the hips' width to
  the shoulders', or a single ellipsoid or box; 60 %: a shoulder bar; depth 85-135 mm;
- pelvis: an ellipsoid, a capsule between the hips or a box, 0-60 mm above the hip points;
- limbs: tapered cones, untapered capsules, or chains of 2-3 ellipsoids (one kind for the arms, one for the
  legs), radii at the reference stature: upper arm 38-62, forearm 26-46, thigh 58-96, shin 38-64 mm;
- hands: a capsule or an ellipsoid; feet: a capsule or a box; a gown is an ellipsoid skirt or a cone; an apron
  an ellipsoid or a slab; caps, masks and hair sit on the drawn head.

All of it is built on the annotated points moved by the person's joint placement (``BodyShape.offsets``), and
thicknesses scale with the stature and the clothing's looseness, as in the twin body. The ``alt`` look's own
body model (:mod:`posenet.synth.body_alt`) is not used: nothing trains on it.
"""

from __future__ import annotations

import numpy as np

from posenet.synth.body import BodyShape, Outfit, flesh_skeleton, gown_cone, tapered_limb
from posenet.synth.primitives import Primitive, box, capsule, ellipsoid, round_cone
from posenet.synth.skeleton_full import LENGTHS, unit


def grammar_primitives(points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape) -> list[Primitive]:
    """Primitives of one person from a full skeleton ``(NUM_FULL, 3)`` (z-up world frame, mm), drawn from
    ``shape.grammar`` (a seed: the same person gets the same body every frame)."""
    rng = np.random.default_rng(shape.grammar)
    u = rng.uniform
    (fwd, left, up), P, mid_sh, mid_hip, spine = flesh_skeleton(points, shape.offsets)
    trunk = float(np.linalg.norm(spine))
    s = float(np.clip(trunk / LENGTHS["trunk"], 0.8, 1.25))
    k = s * outfit.bulk * u(0.9, 1.12)
    sh_half = float(np.linalg.norm(P["left_shoulder"] - P["right_shoulder"])) / 2
    hip_half = float(np.linalg.norm(P["left_hip"] - P["right_hip"])) / 2
    trunk_axes = np.stack([left, fwd, up], 1)
    out: list[Primitive] = []

    def solid(kind, c, radii, axes, mat):  # an ellipsoid or a box with these half sizes
        make = box if kind == "box" else ellipsoid
        out.append(make(c, np.asarray(radii, float), axes, owner, mat))

    def bar(kind, c, half, r, depth, height, mat):  # a horizontal trunk part across the body
        if kind == "capsule":
            out.append(capsule(c + left * max(half - r, 1.0), c - left * max(half - r, 1.0), r, owner, mat))
        else:
            solid(kind, c, (half, depth, height), trunk_axes, mat)

    # Head: the head point anywhere from the face to the skull's middle.
    hd = unit(P["head"] - P["neck"])
    hf = unit(fwd - hd * (fwd @ hd))
    head_axes = np.stack([np.cross(hd, hf), hf, hd], 1)
    head_c = P["head"] + hd * u(-10, 60) * s - hf * u(0, 70) * s
    radii = np.array([u(75, 100), u(85, 110), u(95, 125)]) * s
    head_kind = "box" if rng.random() < 0.15 else "ellipsoid"
    solid(head_kind, head_c, radii * (0.85 if head_kind == "box" else 1.0), head_axes, outfit.skin)
    if outfit.cap is not None:
        solid("ellipsoid", head_c + hd * 0.35 * radii[2] - hf * 0.1 * radii[1], radii * [1.08, 1.08, 0.75],
              head_axes, outfit.cap)  # fmt: skip
        if outfit.hood:
            solid("ellipsoid", head_c - hd * 0.7 * radii[2] - hf * 0.2 * radii[1], radii * [1.1, 0.9, 0.8],
                  head_axes, outfit.cap)  # fmt: skip
    elif outfit.hair is not None:
        solid("ellipsoid", head_c + hd * 0.15 * radii[2] - hf * 0.15 * radii[1], radii * 1.05, head_axes,
              outfit.hair)  # fmt: skip
    if outfit.mask is not None:
        solid("ellipsoid", head_c + hf * 0.75 * radii[1] - hd * 0.35 * radii[2], radii * [0.7, 0.35, 0.45],
              head_axes, outfit.mask)  # fmt: skip
    out.append(
        capsule(P["neck"] - up * 30 * s, head_c - hd * 0.5 * radii[2], u(38, 65) * s, owner, outfit.skin)
    )
    # Trunk.
    depth = u(85, 135) * k
    sh_w, hip_w = sh_half + u(-30, 50) * k, hip_half + u(10, 60) * k
    if rng.random() < 0.75:
        n, kind = int(rng.integers(2, 5)), str(rng.choice(["ellipsoid", "capsule", "box"]))
        lo, hi = u(0.12, 0.3), u(0.8, 0.97)
        for t in np.linspace(lo, hi, n):
            half_h = trunk * (hi - lo) / max(n - 1, 1) * u(0.55, 0.85)
            r = min(depth, half_h + 20 * k) if kind == "capsule" else depth
            bar(kind, mid_hip + spine * t, hip_w + (sh_w - hip_w) * t, r, depth, half_h, outfit.top)
    else:
        kind = "box" if rng.random() < 0.3 else "ellipsoid"
        solid(kind, mid_hip + spine * u(0.45, 0.6), (max(sh_w, hip_w), depth, trunk * u(0.5, 0.65)),
              trunk_axes, outfit.top)  # fmt: skip
    if rng.random() < 0.6:
        drop = up * u(0, 40) * s
        r = u(45, 70) * k
        out.append(capsule(P["left_shoulder"] - drop, P["right_shoulder"] - drop, r, owner, outfit.top))
    pelvis_kind = str(rng.choice(["ellipsoid", "capsule", "box"]))
    pelvis_r = u(85, 120) * k
    bar(pelvis_kind, mid_hip + up * u(0, 60) * s, hip_half + u(20, 70) * k, pelvis_r, pelvis_r,
        u(90, 140) * s, outfit.trousers)  # fmt: skip
    if outfit.apron is not None:
        kind = "box" if rng.random() < 0.5 else "ellipsoid"
        thick = 16.0 if kind == "box" else u(60, 95) * k
        solid(kind, mid_hip + spine * 0.42 + fwd * (depth + (8 if kind == "box" else -40 * k)),
              (sh_half + u(20, 70) * k, thick, trunk * u(0.55, 0.8)), trunk_axes, outfit.apron)  # fmt: skip

    # Limbs: one kind for the arms, one for the legs.
    def limb(kind, a, b, ra, rb, mat):
        length = float(np.linalg.norm(b - a))
        if kind == "cone":
            out.append(tapered_limb(a, b, ra, rb, owner, mat))
        elif kind == "beads" and length > 1:
            d = unit(b - a)
            n = int(rng.integers(2, 4))
            side = unit(np.cross(d, up) if abs(d @ up) < 0.95 else np.cross(d, fwd))
            axes = np.stack([side, np.cross(d, side), d], 1)
            for i in range(n):
                t = (i + 0.5) / n
                r = ra + (rb - ra) * t
                solid("ellipsoid", a + (b - a) * t, (r, r, length / n * u(0.6, 0.8) + r * 0.3), axes, mat)
        else:
            out.append(capsule(a, b, (ra + rb) / 2, owner, mat))

    arm_kind, leg_kind = (str(rng.choice(["cone", "capsule", "beads"])) for _ in range(2))
    ua, fa, th, sh = u(38, 62), u(26, 46), u(58, 96), u(38, 64)
    taper = u(0.6, 1.0)
    hand_kind, foot_kind = rng.random() < 0.5, rng.random() < 0.5
    for side in ("left", "right"):
        limb(arm_kind, P[f"{side}_shoulder"], P[f"{side}_elbow"], ua * k, ua * taper * k, outfit.top)
        limb(arm_kind, P[f"{side}_elbow"], P[f"{side}_wrist"], fa * k, fa * taper * k,
             outfit.top if outfit.gown else outfit.skin)  # fmt: skip
        hand_dir = unit(P[f"{side}_hand"] - P[f"{side}_wrist"])
        if hand_kind:
            out.append(capsule(P[f"{side}_wrist"] + hand_dir * 15 * s, P[f"{side}_hand"] + hand_dir * 15 * s,
                               u(28, 44) * s, owner, outfit.hands))  # fmt: skip
        else:
            c = P[f"{side}_hand"] - hand_dir * 10 * s
            solid("ellipsoid", c, np.array([u(32, 48), u(22, 34), u(45, 65)]) * s, None, outfit.hands)
        limb(leg_kind, P[f"{side}_hip"], P[f"{side}_knee"], th * k, th * taper * k, outfit.trousers)
        limb(leg_kind, P[f"{side}_knee"], P[f"{side}_ankle"], sh * k, sh * taper * k, outfit.trousers)
        toe, ankle = P[f"{side}_toe"], P[f"{side}_ankle"] - up * 30 * s
        if foot_kind:
            out.append(capsule(ankle, toe, u(35, 50) * s, owner, outfit.shoes))
        else:
            f = unit((toe - ankle) - up * ((toe - ankle) @ up))
            R = np.stack([f, np.cross(up, f), up], 1)
            half_len = float(np.linalg.norm(toe - ankle)) / 2 + 20 * s
            solid("box", (toe + ankle) / 2, (half_len, u(40, 55) * s, u(30, 45) * s), R, outfit.shoes)
    if outfit.gown and shape.gown == "cone":
        out += gown_cone(P, mid_hip, up, shape, k, s, owner, outfit.top)
    elif outfit.gown:  # a skirt to below the knees: an ellipsoid or a cone
        knees = (P["left_knee"] + P["right_knee"]) / 2
        ax_up = unit(mid_hip - knees)
        lo = knees - ax_up * u(0, 150) * s
        if rng.random() < 0.5:
            ax_l = unit(left - ax_up * (left @ ax_up))
            axes = np.stack([ax_l, np.cross(ax_l, ax_up), ax_up], 1)
            half = float(np.linalg.norm(mid_hip - lo)) / 2
            solid("ellipsoid", (mid_hip + lo) / 2, (hip_half + u(80, 140) * k, u(120, 170) * k, half), axes,
                  outfit.top)  # fmt: skip
        else:
            ra, rb = hip_half + u(60, 110) * k, hip_half + u(100, 160) * k
            if np.linalg.norm(mid_hip - lo) > abs(ra - rb) + 1:
                out.append(round_cone(mid_hip + up * 40 * s, lo, ra, rb, owner, outfit.top))
    return out
