"""Hard negatives: things in an operating room that a person detector takes for people, never a person themselves.

Each is room furniture (no box, no pose in the annotations), standing or hanging along the room's walls, where an
OR keeps them, their bounding spheres at least 15 cm from every person's joints (``keep_clear``: a sequence's whole walk) and seen by at least one
camera. Kinds (:data:`KINDS`; sizes in mm):

- ``coat_hook``: one to three gowns or coats hanging from hooks on a wall (hanger 1.55-1.9 m up, 0.7-1.2 m long,
  sleeves beside them; a cap on the hook for 40 %);
- ``coat_stand``: a coat stand (a pole on a foot, 1.7-1.9 m) with one to three gowns or coats around it;
- ``apron_rack``: two to five lead aprons side by side on a bar (1.35-1.7 m up), on two legs or on the wall;
- ``stool``: an OR stool (a round seat 0.45-0.75 m up on a column and a star base; a backrest for 30 %);
- ``tower``: a person-sized column of stacked equipment (an endoscopy tower: three to five units on a trolley,
  1.3-1.8 m, a monitor on top for 60 %);
- ``mannequin``: a gown on a dress form (a torso, shoulders and sleeves on a post, a gown skirt to 0.45-0.8 m,
  a head form for 60 %, capped for a third of those).

Their primitives carry the owner ids ``OWNER_HARD_NEGATIVE - k`` (k: the object's index in the frame), room ids
below every other, so that a rendered view's owner map tells which object a pixel shows
(``benchmarks/hard_negatives.py`` counts the detector's false positives per kind); everything else treats them
as the room. The ``random`` and ``mesh`` looks draw them (``--hard-negatives N``) from a generator of their own,
so a frame's other draws stay those without them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from posenet.rig import Rig
from posenet.synth.body import APRON_COLOURS, SCRUB_COLOURS
from posenet.synth.clutter import Placement
from posenet.synth.primitives import (
    OWNER_HARD_NEGATIVE,
    Material,
    Primitive,
    box,
    capsule,
    ellipsoid,
    round_cone,
)
from posenet.synth.rig import intrinsics, world_to_cam
from posenet.synth.room import DARK, GREY, METAL, WHITE_PAINT, yaw_matrix

KINDS = ("coat_hook", "coat_stand", "apron_rack", "stool", "tower", "mannequin")
WALL_KINDS = {"coat_hook": (70.0, 110.0), "apron_rack": (150.0, 320.0)}  # kind -> its distance from the wall
FLOOR_GAP = (300.0, 1100.0)  # the floor kinds' distance from the wall
CLEAR_MM = 150.0  # from every person's joints to the objects' bounding spheres (on the floor plane)
COAT_WHITES = np.array([[0.86, 0.87, 0.88], [0.80, 0.82, 0.85], [0.92, 0.92, 0.90]])  # lab coats
UPHOLSTERY = np.array([[0.05, 0.05, 0.06], [0.10, 0.18, 0.35], [0.30, 0.30, 0.32], [0.12, 0.30, 0.28]])


def _cloth(rng: np.random.Generator) -> Material:
    """An OR gown (the scrubs' colours) or a lab coat, of a textile's grain."""
    rgb = (
        SCRUB_COLOURS[rng.integers(len(SCRUB_COLOURS))]
        if rng.random() < 0.7
        else COAT_WHITES[rng.integers(3)]
    )
    rgb = np.clip(rgb * rng.uniform(0.85, 1.15, 3), 0.01, 0.97)
    return Material(tuple(float(c) for c in rgb), texture=float(rng.uniform(0.02, 0.12)))


def _paint(rng: np.random.Generator, palette: np.ndarray, **kw) -> Material:
    rgb = np.clip(palette[rng.integers(len(palette))] * rng.uniform(0.85, 1.15, 3), 0.01, 0.97)
    return Material(tuple(float(c) for c in rgb), **kw)


def hanging_coat(
    top: np.ndarray, R: np.ndarray, rng: np.random.Generator, material: Material
) -> list[Primitive]:
    """A gown or coat on a hanger whose hook is at ``top (3,)``, its front along ``R``'s local x."""
    length, half_w = rng.uniform(700, 1200), rng.uniform(200, 260)
    depth = rng.uniform(70, 110)
    ax, ay = R[:, 0], R[:, 1]
    chest = top - [0, 0, 330]
    skirt_h = (length - 450) / 2
    prims = [
        ellipsoid(top - [0, 0, 70], [depth, half_w, 70], R, material=material),  # shoulders on the hanger
        ellipsoid(chest, [depth, half_w * 0.95, 300], R, material=material),
        ellipsoid(
            top - [0, 0, 450 + skirt_h],
            [depth * 0.9, half_w * rng.uniform(0.95, 1.2), skirt_h + 60],
            R,
            material=material,
        ),  # fmt: skip
    ]
    sleeve = rng.uniform(480, 620)
    for side in (-1, 1):  # sleeves hanging beside the body, a little in front
        a = top - [0, 0, 90] + ay * side * half_w * 0.95 + ax * 20
        prims.append(capsule(a, a - [0, 0, sleeve] + ay * side * 20, rng.uniform(45, 60), material=material))
    return prims


def coat_hook(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """Gowns or coats on a row of wall hooks; ``pos``: the floor point below the middle hook."""
    n = int(rng.integers(1, 4))
    h, gap = rng.uniform(1550, 1900), rng.uniform(350, 520)
    prims = []
    for k in range(n):
        top = pos + R[:, 1] * (k - (n - 1) / 2) * gap + [0, 0, h]
        prims.append(capsule(top - R[:, 0] * 80, top, 10, material=METAL))  # the hook, from the wall
        prims += hanging_coat(top, R @ yaw_matrix(rng.normal(0, 0.15)), rng, _cloth(rng))
        if rng.random() < 0.4:  # a cap on the hook
            prims.append(ellipsoid(top + [0, 0, 40], [100, 95, 70], R, material=_cloth(rng)))
    return prims


def coat_stand(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """A coat stand with one to three gowns or coats hanging round it."""
    h = rng.uniform(1700, 1900)
    prims = [ellipsoid(pos + [0, 0, 25], [260, 260, 25], material=METAL),
             capsule(pos + [0, 0, 40], pos + [0, 0, h], 18, material=METAL)]  # fmt: skip
    for k in range(int(rng.integers(1, 4))):
        Rk = R @ yaw_matrix(k * 2.1 + rng.normal(0, 0.3))
        prims += hanging_coat(pos + Rk[:, 0] * 150 + [0, 0, h - 80], Rk, rng, _cloth(rng))
    return prims


def apron_rack(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator, on_wall: bool) -> list[Primitive]:
    """Lead aprons side by side on a bar along ``R``'s local y; ``pos``: the floor point below its middle."""
    n, h = int(rng.integers(2, 6)), rng.uniform(1350, 1700)
    width = n * rng.uniform(180, 260)
    ay = R[:, 1]
    a, b = pos + [0, 0, h] - ay * width / 2, pos + [0, 0, h] + ay * width / 2
    prims = [capsule(a, b, 18, material=METAL)]
    if not on_wall:
        for end in (a, b):
            prims += [capsule(end, end * [1, 1, 0] + [0, 0, 40], 18, material=METAL),
                      capsule(end * [1, 1, 0] + [0, 0, 25] - R[:, 0] * 250, end * [1, 1, 0] + [0, 0, 25] + R[:, 0] * 250,
                              20, material=METAL)]  # fmt: skip
    for k in range(n):
        mat = _paint(
            rng, APRON_COLOURS, texture=float(rng.uniform(0.02, 0.08)), specular=float(rng.uniform(0, 0.3))
        )
        Rk = R @ yaw_matrix(rng.normal(0, 0.12))
        half_h = rng.uniform(380, 550)
        top = a + ay * (k + 0.5) * width / n + R[:, 0] * (30 + 25 * (k % 2))
        prims += [ellipsoid(top - [0, 0, 60], [40, rng.uniform(170, 220), 80], Rk, material=mat),  # the collar
                  box(top - [0, 0, 60 + half_h], [22, rng.uniform(210, 270), half_h], Rk, material=mat)]  # fmt: skip
    return prims


def stool(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """An OR stool: a round seat on a gas column and a five-legged base; some have a backrest."""
    h, r = rng.uniform(450, 750), rng.uniform(170, 230)
    seat = _paint(rng, UPHOLSTERY, texture=0.03, specular=float(rng.uniform(0.1, 0.5)))
    prims = [ellipsoid(pos + [0, 0, h], [r, r, 45], R, material=seat),
             capsule(pos + [0, 0, 70], pos + [0, 0, h - 30], 28, material=METAL)]  # fmt: skip
    for k in range(5):
        d = yaw_matrix(k * 2 * np.pi / 5) @ R[:, 0]
        prims.append(capsule(pos + [0, 0, 60], pos + d * 290 + [0, 0, 35], 16, material=METAL))
    if rng.random() < 0.3:
        back = pos - R[:, 0] * (r - 20) + [0, 0, h + 250]
        prims += [capsule(pos + [0, 0, h] - R[:, 0] * (r - 20), back - [0, 0, 120], 15, material=METAL),
                  box(back, [30, r * 0.9, 110], R, material=seat)]  # fmt: skip
    return prims


def tower(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """An equipment tower: units stacked on a trolley to a person's height, often a monitor on top."""
    half = np.array([rng.uniform(220, 300), rng.uniform(250, 320), 0.0])
    prims = [box(pos + [0, 0, 110], [half[0] + 30, half[1] + 30, 40], R, material=GREY)]
    z, top = 150.0, rng.uniform(1300, 1800)
    shades = (WHITE_PAINT, GREY, DARK, METAL)
    while z < top - 100:
        hh = min(rng.uniform(60, 200), (top - z) / 2)
        unit = (
            shades[rng.integers(len(shades))] if rng.random() < 0.6 else _paint(rng, COAT_WHITES * 0.6 + 0.1)
        )
        prims.append(
            box(pos + [0, 0, z + hh], [half[0] * rng.uniform(0.85, 1.0), half[1], hh - 4], R, material=unit)
        )
        z += 2 * hh
    if rng.random() < 0.6:
        prims += [capsule(pos + [0, 0, z], pos + [0, 0, z + 120], 25, material=METAL),
                  box(pos + [0, 0, z + 120 + rng.uniform(150, 220)], [30, rng.uniform(230, 320), 190], R,
                      material=DARK)]  # fmt: skip
    return prims


def mannequin(pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """A gown on a dress form: torso, shoulders and sleeves on a post, a gown skirt, maybe a (capped) head form."""
    gown = _cloth(rng)
    form = (
        Material((0.85, 0.8, 0.72), texture=0.02)
        if rng.random() < 0.5
        else Material((0.1, 0.1, 0.1), texture=0.02)
    )
    s = rng.uniform(0.9, 1.1)
    chest, shoulders = 1300 * s, 1470 * s
    width = rng.uniform(190, 230)
    prims = [ellipsoid(pos + [0, 0, 25], [230, 230, 25], material=METAL),
             capsule(pos + [0, 0, 40], pos + [0, 0, chest - 300], 20, material=METAL),
             ellipsoid(pos + [0, 0, chest], [rng.uniform(110, 140), width, 260 * s], R, material=gown),
             ellipsoid(pos + [0, 0, shoulders], [105, width + 30, 75], R, material=gown),
             round_cone(pos + [0, 0, chest - 150], pos + [0, 0, rng.uniform(450, 800)], width, width + rng.uniform(40, 140),
                        material=gown)]  # fmt: skip
    for side in (-1, 1):
        a = pos + [0, 0, shoulders - 30] + R[:, 1] * side * (width + 20)
        prims.append(capsule(a, a - [0, 0, rng.uniform(450, 600)] + R[:, 1] * side * 40, 50, material=gown))
    if rng.random() < 0.6:
        neck = pos + [0, 0, shoulders + 60]
        prims += [capsule(neck - [0, 0, 50], neck + [0, 0, 50], 45, material=form),
                  ellipsoid(neck + [0, 0, 150], [95, 80, 115], R, material=form)]  # fmt: skip
        if rng.random() < 1 / 3:
            prims.append(ellipsoid(neck + [0, 0, 200], [105, 95, 80], R, material=_cloth(rng)))
    return prims


def hard_negative(kind: str, pos: np.ndarray, R: np.ndarray, rng: np.random.Generator) -> list[Primitive]:
    """The primitives of one hard negative of ``kind`` whose foot (or wall point) is the floor point ``pos (3,)``,
    its front along ``R (3, 3)``'s local x."""
    if kind == "coat_hook":
        return coat_hook(pos, R, rng)
    if kind == "coat_stand":
        return coat_stand(pos, R, rng)
    if kind == "apron_rack":
        return apron_rack(pos, R, rng, on_wall=rng.random() < 0.4)
    if kind == "stool":
        return stool(pos, R, rng)
    if kind == "tower":
        return tower(pos, R, rng)
    if kind == "mannequin":
        return mannequin(pos, R, rng)
    raise ValueError(f"unknown hard negative kind {kind!r}; expected one of {KINDS}")


def _clearance(prims: list[Primitive], points: np.ndarray) -> float:
    """mm on the floor plane from the floor points ``points (N, 2)`` to the nearest of ``prims``' bounding spheres
    (negative: inside one)."""
    spheres = [s for p in prims for s in p.bounding_spheres()]
    centres = np.array([c[:2] for c, _ in spheres])  # (S, 2)
    radii = np.array([r for _, r in spheres])
    return float((np.linalg.norm(points[:, None] - centres[None], axis=-1) - radii).min())


def _seen(rig: Rig, prims: list[Primitive]) -> bool:
    """Whether some camera has the object's centre in its image, in front of it."""
    c = np.mean([p.center for p in prims], axis=0)
    T = world_to_cam(rig)
    pc = c @ T[:, :3, :3].transpose(0, 2, 1) + T[:, :3, 3]  # (V, 3)
    for K, (x, y, z) in zip(intrinsics(rig), pc, strict=True):
        if z > 500 and 0 <= K.fx * x / z + K.cx < K.width and 0 <= K.fy * y / z + K.cy < K.height:
            return True
    return False


def add_hard_negatives(frame, rig: Rig, rng: np.random.Generator, count: int,
                       protect: set[tuple[int, int]] | None = None, keep_clear: np.ndarray | None = None,
                       kinds: tuple[str, ...] = KINDS, tries: int = 8) -> list[str]:  # fmt: skip
    """Add up to ``count`` hard negatives of ``kinds`` along the walls of ``frame``'s room (module docstring),
    keeping :data:`CLEAR_MM` from every joint of ``frame``'s persons and from the floor points ``keep_clear (N, 2)``
    and passing :class:`~posenet.synth.clutter.Placement`'s checks; returns the kinds added, in order (the k-th
    has the owner id ``OWNER_HARD_NEGATIVE - k``)."""
    if count == 0:
        return []
    place = Placement(frame, rig, protect)
    if place.shell is None:
        return []
    centre, half = place.shell.center[:2], place.shell.size[:2]
    clear = [p.points[:, :2] for p in frame.persons]
    if keep_clear is not None:
        clear.append(np.asarray(keep_clear, float).reshape(-1, 2))
    clear = np.concatenate(clear) if clear else np.zeros((0, 2))
    added: list[str] = []
    for _ in range(count):
        kind = str(kinds[rng.integers(len(kinds))])
        for _ in range(tries):
            axis, side = int(rng.integers(2)), float(rng.choice([-1.0, 1.0]))
            gap = rng.uniform(*WALL_KINDS.get(kind, FLOOR_GAP))
            pos = np.append(centre, 0.0)
            pos[axis] += side * (half[axis] - gap)
            pos[1 - axis] += rng.uniform(-1, 1) * (half[1 - axis] - 500)
            inward = np.zeros(3)
            inward[axis] = -side
            yaw = float(
                np.arctan2(inward[1], inward[0]) + (0.0 if kind in WALL_KINDS else rng.normal(0, 0.5))
            )
            R = yaw_matrix(yaw)
            owner = OWNER_HARD_NEGATIVE - len(added)
            prims = [replace(p, owner=owner) for p in hard_negative(kind, pos, R, rng)]
            if len(clear) and _clearance(prims, clear) < CLEAR_MM:
                continue
            if not _seen(rig, prims) or not place.fits(prims) or not place.add(prims):
                continue
            added.append(kind)
            break
    return added
