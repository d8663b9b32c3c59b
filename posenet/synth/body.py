"""Articulated bodies from smooth primitives, dressed in OR clothing.

:func:`body_primitives` turns a full skeleton (:mod:`posenet.synth.skeleton_full`, z up, mm) into about
twenty capsules, round cones and ellipsoids: head, cap, mask, neck, shoulders, chest, belly, pelvis, arms,
gloved hands, thighs, shins and shoes (limbs taper from joint to joint), plus a gown skirt or a lead apron
when the outfit has one. Thicknesses scale with the stature (trunk length); colours come from an
:class:`Outfit` drawn by :func:`sample_outfit`. Every size, and where the annotated joints sit inside the
body, is a field of :class:`BodyShape`, whose defaults are the ``twin`` look's body; the ``random`` look draws
them per person (:mod:`posenet.synth.looks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posenet.synth.primitives import CONE, ELLIPSOID, Material, Primitive, capsule, ellipsoid, round_cone
from posenet.synth.skeleton_full import LENGTHS, F, body_frame, unit

# Linear-RGB reflectances. Scrubs and gowns: the blues and greens of OR textiles.
SCRUB_COLOURS = np.array(
    [
        [0.10, 0.22, 0.45],
        [0.15, 0.35, 0.55],
        [0.25, 0.45, 0.60],
        [0.05, 0.12, 0.30],  # blues
        [0.12, 0.38, 0.33],
        [0.20, 0.45, 0.40],
        [0.30, 0.50, 0.42],
        [0.08, 0.28, 0.22],  # greens
        [0.35, 0.55, 0.65],
        [0.45, 0.60, 0.55],  # washed-out light blue / sage
    ]
)
SKIN_TONES = np.array(
    [
        [0.80, 0.60, 0.50],
        [0.70, 0.50, 0.38],
        [0.55, 0.38, 0.28],
        [0.40, 0.26, 0.18],
        [0.25, 0.16, 0.11],
    ]
)
GLOVE_COLOURS = np.array([[0.85, 0.78, 0.62], [0.90, 0.90, 0.88], [0.30, 0.45, 0.75], [0.75, 0.68, 0.55]])
MASK_COLOURS = np.array([[0.55, 0.70, 0.85], [0.85, 0.88, 0.90], [0.45, 0.65, 0.55]])
APRON_COLOURS = np.array([[0.25, 0.28, 0.35], [0.35, 0.30, 0.45], [0.15, 0.25, 0.45], [0.45, 0.45, 0.45]])
SHOE_COLOURS = np.array([[0.85, 0.85, 0.85], [0.05, 0.05, 0.06], [0.20, 0.35, 0.60], [0.15, 0.45, 0.35]])


@dataclass(frozen=True)
class Outfit:
    """What a person wears (materials) and which optional garments they have."""

    top: Material
    trousers: Material
    cap: Material | None  # None: bare head (hair, if any)
    mask: Material | None
    skin: Material
    hands: Material  # gloves, or skin
    shoes: Material
    gown: bool = False  # a long gown over the scrubs (the skirt covers the thighs)
    apron: Material | None = None  # a lead apron in front of the trunk
    bulk: float = 1.0  # how loose the clothing is (scales the thicknesses)
    hair: Material | None = None  # drawn where a cap does not cover it
    hair_bun: bool = False  # a bun at the back of the head
    hood: bool = False  # a surgical hood: the cap reaches down over the neck


@dataclass(frozen=True)
class BodyShape:
    """Sizes of one body, in mm at the reference stature (they scale with it), and where its annotated joints
    sit inside it. The defaults are the ``twin`` look's body.

    ``offsets (NUM_FULL, 3)``: per skeleton point, how far the anatomical joint that the flesh is built on
    lies from the annotated point, in the trunk's frame (forward, outward for the point's side, up); None
    means the flesh is built on the annotated points.
    """

    head: float = 1.0  # skull size factor
    head_out: float = 1.3  # skull centre along neck->head, in units of that distance
    head_back: float = 10.0  # and this far behind the face
    neck: float = 50.0
    shoulder: float = 62.0  # radius of the shoulder bar
    shoulder_drop: float = 15.0  # the bar hangs this far below the shoulder points
    chest_side: float = 40.0  # beyond half the shoulder width
    chest_depth: float = 105.0
    chest_height: float = 0.42  # half height, share of the trunk
    belly_side: float = 30.0  # beyond half the hip width
    belly_depth: float = 98.0
    belly_height: float = 0.36
    belly: float = 0.0  # > 0: a paunch this deep in front of the belly
    pelvis_side: float = 55.0
    pelvis_depth: float = 105.0
    pelvis_height: float = 125.0
    arm: tuple[float, float, float, float] = (52.0, 40.0, 39.0, 29.0)  # upper arm ends, forearm ends
    hand: float = 34.0
    leg: tuple[float, float, float, float] = (82.0, 56.0, 54.0, 38.0)  # thigh ends, shin ends
    shoe: float = 42.0
    skirt_side: float = 110.0  # gown skirt, beyond half the hip width
    skirt_depth: float = 150.0
    skirt_extra: float = 60.0  # reaches this far below the knees
    apron_side: float = 60.0
    apron_depth: float = 95.0
    apron_height: float = 0.75
    offsets: np.ndarray | None = None
    # A gown of a drawn cut instead of the body model's own skirt (the random look's ``gowns="mixed"``): "cone",
    # from gown_top above the hip midpoint down to gown_low below the knees, flaring from gown_radii[0] to
    # gown_radii[1] beyond half the hip width (:func:`gown_cone`). None: the body model's own skirt.
    gown: str | None = None
    gown_top: float = 40.0
    gown_radii: tuple[float, float] = (90.0, 130.0)
    gown_low: float = 90.0
    # Only these regions (of BODY_REGIONS) are built by this body model, the rest by the twin's construction
    # with the twin's sizes (``--look-parts body:REGION``, posenet.synth.scene.hybrid_primitives). None: all.
    regions: tuple[str, ...] | None = None
    model: str = "twin"  # "alt": the alt look's own body model (posenet.synth.body_alt); "grammar":
    # primitives of drawn kinds (posenet.synth.body_grammar), drawn from the seed ``grammar``
    grammar: int | None = None
    mesh: int | None = None  # model "mesh": the seed of the person's anny body (posenet.synth.mesh_body)


TWIN_SHAPE = BodyShape()
# A body's regions, for bodies built partly by another model (BodyShape.regions): each primitive belongs to the
# region of the annotated point nearest its centre, except the gown, the last primitive of every body model.
BODY_REGIONS = ("head", "trunk", "arms", "legs", "gown")
REGION_POINTS = {
    "head": ("head", "neck"),
    "trunk": ("left_shoulder", "right_shoulder", "left_hip", "right_hip"),
    "arms": tuple(f"{s}_{j}" for s in ("left", "right") for j in ("elbow", "wrist", "hand")),
    "legs": tuple(f"{s}_{j}" for s in ("left", "right") for j in ("knee", "ankle", "toe")),
}


def primitive_regions(prims: list[Primitive], points: np.ndarray, gown: bool) -> list[str]:
    """The region (:data:`BODY_REGIONS`) of each of one body's primitives, built on ``points (NUM_FULL, 3)``;
    ``gown``: whether the outfit has one (then the last primitive is the gown, when the body model drew one)."""
    names = [n for pts in REGION_POINTS.values() for n in pts]
    region_of = [r for r, pts in REGION_POINTS.items() for _ in pts]
    anchors = points[[F[n] for n in names]]  # (A, 3)
    centres = np.array([p.center for p in prims], float).reshape(-1, 3)
    nearest = np.linalg.norm(centres[:, None] - anchors[None], axis=-1).argmin(1)
    out = [region_of[i] for i in nearest]
    if gown and prims and prims[-1].kind in (CONE, ELLIPSOID) and out[-1] in ("legs", "trunk"):
        out[-1] = "gown"
    return out


def _cloth(rgb: np.ndarray, rng: np.random.Generator, texture: float = 0.05) -> Material:
    shade = np.clip(rgb * rng.uniform(0.85, 1.15, 3), 0.02, 0.95)
    return Material(tuple(float(c) for c in shade), ir_dropout=0.0, texture=texture)


def sample_outfit(rng: np.random.Generator, role: str = "clinician") -> Outfit:
    """A random OR outfit; ``role="patient"`` gives a light hospital gown and no cap or mask."""
    skin_rgb = SKIN_TONES[rng.integers(len(SKIN_TONES))]
    skin = Material(tuple(float(c) for c in np.clip(skin_rgb * rng.uniform(0.9, 1.1, 3), 0, 1)), texture=0.02)
    if role == "patient":
        gown = _cloth(np.array([0.6, 0.7, 0.8]), rng)
        return Outfit(gown, gown, skin, None, skin, skin, skin, gown=False, bulk=1.0)
    scrub = SCRUB_COLOURS[rng.integers(len(SCRUB_COLOURS))]
    top = _cloth(scrub, rng)
    trousers = top if rng.random() < 0.8 else _cloth(SCRUB_COLOURS[rng.integers(len(SCRUB_COLOURS))], rng)
    cap_rgb = scrub if rng.random() < 0.5 else SCRUB_COLOURS[rng.integers(len(SCRUB_COLOURS))]
    if rng.random() < 0.15:  # white or patterned disposable caps
        cap_rgb = np.array([0.85, 0.85, 0.88])
    gloves = rng.random() < 0.6
    hands = _cloth(GLOVE_COLOURS[rng.integers(len(GLOVE_COLOURS))], rng, 0.02) if gloves else skin
    mask = _cloth(MASK_COLOURS[rng.integers(len(MASK_COLOURS))], rng, 0.02) if rng.random() < 0.8 else None
    shoes_rgb = SHOE_COLOURS[rng.integers(len(SHOE_COLOURS))]
    shoes = Material(tuple(float(c) for c in shoes_rgb), ir_dropout=0.3 if shoes_rgb.max() < 0.1 else 0.0)
    gown = rng.random() < 0.35
    if gown:  # a surgical gown replaces the scrub top with a (usually darker or lighter) gown
        top = _cloth(SCRUB_COLOURS[rng.integers(len(SCRUB_COLOURS))], rng)
    apron = None
    if rng.random() < 0.15:
        apron = Material(
            tuple(float(c) for c in APRON_COLOURS[rng.integers(len(APRON_COLOURS))]),
            texture=0.02,
            specular=0.15,
        )
    return Outfit(
        top,
        trousers,
        _cloth(cap_rgb, rng),
        mask,
        skin,
        hands,
        shoes,
        gown,
        apron,
        bulk=float(rng.uniform(0.92, 1.1)),
    )


def anatomical_points(points: np.ndarray, offsets: np.ndarray | None) -> np.ndarray:
    """The skeleton that the flesh is built on: ``points (NUM_FULL, 3)`` moved by ``offsets (NUM_FULL, 3)``
    (forward, outward, up in the trunk's frame; see :class:`BodyShape`)."""
    if offsets is None:
        return points
    fwd, left, up = body_frame(points)
    side = np.array([1.0 if n.startswith("left") else -1.0 if n.startswith("right") else 0.0 for n in F])
    return points + offsets[:, :1] * fwd + (offsets[:, 1:2] * side[:, None]) * left + offsets[:, 2:] * up


def flesh_skeleton(points: np.ndarray, offsets: np.ndarray | None):
    """What every body model builds on: the trunk's ``(fwd, left, up)`` axes of the annotated ``points``, the
    anatomical points by name (moved by ``offsets``, :func:`anatomical_points`), the shoulders' and hips'
    midpoints and the spine between them."""
    axes = body_frame(points)
    points = anatomical_points(points, offsets)
    P = {name: points[i] for name, i in F.items()}
    mid_sh = (P["left_shoulder"] + P["right_shoulder"]) / 2
    mid_hip = (P["left_hip"] + P["right_hip"]) / 2
    return axes, P, mid_sh, mid_hip, mid_sh - mid_hip


def tapered_limb(a, b, ra: float, rb: float, owner: int, material: Material) -> Primitive:
    """A limb tapering from radius ``ra`` at ``a`` to ``rb`` at ``b``; a bone shorter than the taper (odd
    annotations) stays a capsule of the mean radius."""
    if np.linalg.norm(b - a) > abs(ra - rb) + 1:
        return round_cone(a, b, ra, rb, owner, material)
    return capsule(a, b, (ra + rb) / 2, owner, material)


def gown_cone(
    P: dict, mid_hip: np.ndarray, up: np.ndarray, shape: BodyShape, k: float, s: float, owner: int, material
) -> list[Primitive]:
    """The drawn gown of ``shape`` (``shape.gown == "cone"``), for any body model: a cone from ``gown_top`` mm
    above the hip midpoint to ``gown_low`` mm below the knees, ``gown_radii`` mm beyond half the hip width at
    its top and bottom (thicknesses scale with ``k``, lengths with ``s``, as the body's own)."""
    knees = (P["left_knee"] + P["right_knee"]) / 2
    hip_half = float(np.linalg.norm(P["left_hip"] - P["right_hip"])) / 2
    top = mid_hip + up * shape.gown_top * s
    low = knees - unit(mid_hip - knees) * shape.gown_low * s
    ra, rb = (hip_half + r * k for r in shape.gown_radii)
    if np.linalg.norm(top - low) <= abs(ra - rb) + 1:  # a gown shorter than its flare (odd annotations)
        return []
    return [round_cone(top, low, ra, rb, owner, material)]


def body_primitives(
    points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape = TWIN_SHAPE
) -> list[Primitive]:
    """Primitives of one person from a full skeleton ``(NUM_FULL, 3)`` (z-up world frame, mm)."""
    b = shape
    (fwd, left, up), P, mid_sh, mid_hip, spine = flesh_skeleton(points, b.offsets)
    trunk = float(np.linalg.norm(spine))
    s = float(np.clip(trunk / LENGTHS["trunk"], 0.8, 1.25))
    k = s * outfit.bulk  # clothing thickness
    sh_w = float(np.linalg.norm(P["left_shoulder"] - P["right_shoulder"]))
    hip_w = float(np.linalg.norm(P["left_hip"] - P["right_hip"]))
    out: list[Primitive] = []

    def cap_(a, b, r, mat):
        out.append(capsule(a, b, r, owner, mat))

    def limb(a, b, ra, rb, mat):
        out.append(tapered_limb(a, b, ra, rb, owner, mat))

    def ell(c, radii, axes, mat):
        out.append(ellipsoid(c, radii, np.stack(axes, axis=1), owner, mat))

    # Head: MVOR's head point sits at the face; the skull centre is a little further from the neck.
    hd = unit(P["head"] - P["neck"])
    hf = unit(fwd - hd * (fwd @ hd))
    hl = np.cross(hd, hf)
    hs = s * b.head
    head_c = P["neck"] + hd * b.head_out * np.linalg.norm(P["head"] - P["neck"]) - hf * b.head_back * s
    ell(head_c, np.array([72, 90, 108]) * hs, (hl, hf, hd), outfit.skin)
    if outfit.hair is not None:  # under the cap only the back of the head shows
        ell(head_c + hd * 12 * hs - hf * 14 * hs, np.array([76, 88, 100]) * hs, (hl, hf, hd), outfit.hair)
        if outfit.hair_bun:
            ell(head_c - hf * 95 * hs + hd * 10 * hs, np.array([40, 36, 40]) * hs, (hl, hf, hd), outfit.hair)
    if outfit.cap is not None:
        ell(head_c + hd * 30 * hs - hf * 12 * hs, np.array([80, 96, 84]) * hs, (hl, hf, hd), outfit.cap)
        if outfit.hood:  # down the back and the sides of the neck
            ell(head_c - hd * 70 * hs - hf * 20 * hs, np.array([82, 80, 90]) * hs, (hl, hf, hd), outfit.cap)
    if outfit.mask is not None:
        ell(head_c + hf * 62 * hs - hd * 38 * hs, np.array([58, 36, 46]) * hs, (hl, hf, hd), outfit.mask)
    cap_(P["neck"] - up * 20 * s, head_c - hd * 40 * hs, b.neck * s, outfit.skin)
    # Trunk: shoulder bar, chest, belly and pelvis ellipsoids in the trunk's frame.
    drop = up * b.shoulder_drop * s
    cap_(P["left_shoulder"] - drop, P["right_shoulder"] - drop, b.shoulder * k, outfit.top)
    axes = (left, fwd, up)
    ell(
        mid_hip + (mid_sh - mid_hip) * 0.68,
        np.array([sh_w / 2 + b.chest_side * k, b.chest_depth * k, b.chest_height * trunk]),
        axes,
        outfit.top,
    )
    ell(
        mid_hip + (mid_sh - mid_hip) * 0.32,
        np.array([hip_w / 2 + b.belly_side * k, b.belly_depth * k, b.belly_height * trunk]),
        axes,
        outfit.top,
    )
    if b.belly > 0:
        ell(
            mid_hip + (mid_sh - mid_hip) * 0.3 + fwd * (b.belly_depth * k + b.belly - 120 * s),
            np.array([hip_w / 2, 120 * s, 0.3 * trunk]),
            axes,
            outfit.apron if outfit.apron is not None else outfit.top,
        )
    ell(
        mid_hip - up * 15 * s,
        np.array([hip_w / 2 + b.pelvis_side * k, b.pelvis_depth * k, b.pelvis_height * s]),
        axes,
        outfit.trousers,
    )
    if outfit.apron is not None:
        ell(
            mid_hip + (mid_sh - mid_hip) * 0.45 + fwd * 45 * k - up * 60 * s,
            np.array([sh_w / 2 + b.apron_side * k, b.apron_depth * k, b.apron_height * trunk]),
            axes,
            outfit.apron,
        )
    # Arms and hands.
    ua, ub, fa, fb = b.arm
    for side in ("left", "right"):
        limb(P[f"{side}_shoulder"], P[f"{side}_elbow"], ua * k, ub * k, outfit.top)
        limb(
            P[f"{side}_elbow"], P[f"{side}_wrist"], fa * k, fb * k, outfit.top if outfit.gown else outfit.skin
        )
        hand_dir = unit(P[f"{side}_hand"] - P[f"{side}_wrist"])
        cap_(
            P[f"{side}_wrist"] + hand_dir * 15 * s,
            P[f"{side}_hand"] + hand_dir * 20 * s,
            b.hand * s,
            outfit.hands,
        )
    # Legs and shoes.
    ta, tb, sa, sb = b.leg
    for side in ("left", "right"):
        limb(P[f"{side}_hip"], P[f"{side}_knee"], ta * k, tb * k, outfit.trousers)
        limb(P[f"{side}_knee"], P[f"{side}_ankle"], sa * k, sb * k, outfit.trousers)
        cap_(P[f"{side}_ankle"] - up * 25 * s, P[f"{side}_toe"], b.shoe * s, outfit.shoes)
    if outfit.gown and b.gown == "cone":
        out += gown_cone(P, mid_hip, up, b, k, s, owner, outfit.top)
    elif outfit.gown:  # a gown skirt down to the knees
        knees = (P["left_knee"] + P["right_knee"]) / 2
        c = (mid_hip + knees) / 2
        ax_up = unit(mid_hip - knees)
        ax_l = unit(left - ax_up * (left @ ax_up))
        ax_f = np.cross(ax_l, ax_up)
        half = float(np.linalg.norm(mid_hip - knees)) / 2 + b.skirt_extra * s
        ell(
            c,
            np.array([hip_w / 2 + b.skirt_side * k, b.skirt_depth * k, half]),
            (ax_l, ax_f, ax_up),
            outfit.top,
        )
    return out
