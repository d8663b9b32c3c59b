"""Occluders that a look adds to a frame: their kind, count, size and placement.

Each occluder is placed between a random camera and a random person (15-80 % of the way), so that it hides
part of someone in some view, or, for floor-standing kinds, on the floor below that point. A candidate is
rejected (and redrawn, up to a few times) when it would stand within 40 cm of a person, reach the ceiling,
hang within 60 cm of a camera, fill more than 35 % of an image, or cover more than 35 % of the box of a
``protect`` (view, person) pair in front of that person (the MVOR twin's people that MVOR shows). An occluder
that passes is kept only if, rendered at quarter resolution, it leaves every protected person at least 75 % of
their visible pixels and, where it takes any, at least twice the pixels that a box needs. Kinds:
``random`` draws boom panels, IV poles, carts, drape screens, lamps and instrument stands; ``alt`` has its
own supply columns, horizontal booms and shelf trolleys.
"""

from __future__ import annotations

import numpy as np

from posenet.rig import Rig
from posenet.synth.boxes import covered, project_boxes
from posenet.synth.primitives import SHELL, Material, Primitive, box, capsule, ellipsoid
from posenet.synth.rig import cam_to_world, intrinsics, world_to_cam
from posenet.synth.room import DARK, METAL, WHITE_PAINT, yaw_matrix
from posenet.synth.skeleton_full import F

FLOOR_KINDS = {"pole", "cart", "screen", "stand", "column", "trolley"}
ALT_GREY = Material((0.62, 0.64, 0.66), texture=0.02, specular=0.25)


def _random_material(rng: np.random.Generator) -> Material:
    rgb = rng.uniform(0.05, 0.9) * rng.uniform(0.8, 1.2, 3)
    return Material(tuple(float(c) for c in np.clip(rgb, 0.02, 0.95)), ir_dropout=float(rng.uniform(0, 0.3)),
                    texture=float(rng.uniform(0.01, 0.08)), specular=float(rng.uniform(0, 0.7)))  # fmt: skip


def occluder(kind: str, pos: np.ndarray, yaw: float, scale: float, ceiling: float, rng: np.random.Generator,
             material: Material | None = None) -> list[Primitive]:  # fmt: skip
    """The primitives of one occluder of ``kind`` at ``pos (3,)`` (floor kinds: its xy on the floor)."""
    R = yaw_matrix(yaw)
    u = rng.uniform
    floor = np.array([pos[0], pos[1], 0.0])
    m = material
    if kind == "panel":  # a screen on a boom, facing yaw
        half = np.array([35.0, u(200, 420), u(150, 320)]) * scale
        return [box(pos, half, R, material=m or DARK),
                capsule(pos + [0, 0, half[2]], [pos[0], pos[1], ceiling], 30, material=m or WHITE_PAINT)]  # fmt: skip
    if kind == "pole":
        h = u(1600, 2100)
        return [capsule(floor + [0, 0, 40], floor + [0, 0, h], u(12, 25) * scale, material=m or METAL),
                ellipsoid(floor + [0, 70, h - 200], np.array([60, 30, 110]) * scale,
                          material=Material((0.8, 0.85, 0.9), texture=0.01))]  # fmt: skip
    if kind == "cart":
        h = u(700, 1300) * scale
        half = np.array([u(200, 400), u(180, 300), h / 2]) * [scale, scale, 1]
        return [box(floor + [0, 0, h / 2 + 80], half, R, material=m or WHITE_PAINT)]
    if kind == "screen":
        w, h = u(500, 1000) * scale, min(u(1200, 1900) * scale, ceiling - 300)
        return [box(floor + [0, 0, h / 2 + 100], [25, w / 2, h / 2], R, material=m or _random_material(rng))]
    if kind == "lamp":
        r = u(250, 400) * scale
        c = np.array([pos[0], pos[1], max(pos[2], 1700.0)])
        return [ellipsoid(c, [r, r, 90 * scale], R, material=m or WHITE_PAINT),
                capsule(c + [0, 0, 80], [c[0] + u(-400, 400), c[1] + u(-400, 400), ceiling], 35,
                        material=m or WHITE_PAINT)]  # fmt: skip
    if kind == "stand":  # an instrument (Mayo) stand: a tray on a pole
        h = u(900, 1300)
        tray = np.array([u(220, 330), u(160, 240), 20]) * [scale, scale, 1]
        return [box(floor + [0, 0, h], tray, R, material=m or METAL),
                capsule(floor + [0, 0, 30], floor + [0, 0, h - 20], 20, material=m or METAL)]  # fmt: skip
    if kind == "column":  # alt: a floor-to-ceiling supply column
        return [capsule(floor + [0, 0, 150], [pos[0], pos[1], ceiling - 10], 170.0, material=ALT_GREY)]
    if kind == "boom":  # alt: a horizontal boom arm at head height
        a = np.array([pos[0], pos[1], 1950.0]) - R[:, 0] * 600
        b = a + R[:, 0] * 1200
        return [capsule(a, b, 65.0, material=ALT_GREY),
                capsule(a, [a[0], a[1], ceiling], 50.0, material=ALT_GREY)]  # fmt: skip
    if kind == "trolley":  # alt: three shelves on four legs
        out = [box(floor + [0, 0, z], [300, 220, 15], R, material=ALT_GREY) for z in (250.0, 650.0, 1050.0)]
        for sx in (-1, 1):
            for sy in (-1, 1):
                leg = floor + R @ np.array([sx * 280.0, sy * 200.0, 0])
                out.append(capsule(leg + [0, 0, 60], leg + [0, 0, 1060], 14.0, material=METAL))
        return out
    raise ValueError(f"unknown occluder kind {kind!r}")


def _sphere_corners(prims: list[Primitive]) -> np.ndarray:
    """(8 S, 3) corners of the cubes around the primitives' bounding spheres."""
    pts = []
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    for p in prims:
        for c, r in p.bounding_spheres():
            pts.append(c + signs * r)
    return np.concatenate(pts)


class Placement:
    """The checks that every object added to a frame's room passes (occluders here, hard negatives in
    :mod:`~posenet.synth.hard_negatives`): it stays below the ceiling (unless it hangs from it), 60 cm from every
    camera, fills at most 35 % of any image, and leaves the ``protect`` (view, person) pairs visible (module
    docstring). It draws nothing from any generator."""

    def __init__(self, frame, rig: Rig, protect: set[tuple[int, int]] | None = None) -> None:
        self.frame, self.rig, self.protect = frame, rig, protect
        shell = next((p for p in frame.room if p.kind == SHELL), None)
        self.shell = shell
        self.ceiling = float(shell.center[2] + shell.size[2]) if shell is not None else 2900.0
        self.cams = cam_to_world(rig)[:, :3, 3]  # (V, 3)
        self.T = world_to_cam(rig)
        self.sil = self.seen = None
        if protect:
            from posenet.synth.scene import silhouettes, visible_pixels  # scene imports the body models

            self.sil = silhouettes(frame, rig)
            self.seen = visible_pixels(frame, rig)

    def fits(self, prims: list[Primitive], hangs: bool = False) -> bool:
        """Whether ``prims`` pass the geometric checks (``hangs``: it may reach the ceiling)."""
        corners = _sphere_corners(prims)
        if corners[:, 2].max() > self.ceiling + 50 and not hangs:
            return False
        if np.linalg.norm(self.cams[:, None] - corners[None], axis=-1).min() < 600:
            return False
        depth = (corners @ self.T[:, 2, :3].T + self.T[:, 2, 3]).T  # (V, N) z in each camera
        proj = project_boxes(self.rig, corners[None])[:, 0]  # (V, 4)
        area = (proj[:, 2] - proj[:, 0]) * (proj[:, 3] - proj[:, 1])
        sizes = np.array([K.width * K.height for K in intrinsics(self.rig)])
        if ((area > 0.35 * sizes) & (depth.max(1) > 0)).any():
            return False
        sil = self.sil
        return sil is None or not any(
            (w, q) in sil and depth[w].min() < sil[(w, q)][1] and covered(proj[w], sil[(w, q)][0]) > 0.35
            for w, q in self.protect
        )

    def add(self, prims: list[Primitive]) -> bool:
        """Add ``prims`` to the room unless they take too much of a protected person (then nothing is added)."""
        self.frame.room.extend(prims)
        if self.seen is not None:
            from posenet.synth.scene import visible_pixels

            now = visible_pixels(self.frame, self.rig)
            if not all(
                _keeps_box(self.seen[k], now[k], self.sil[k][2]) for k in self.protect if k in self.sil
            ):
                del self.frame.room[-len(prims) :]
                return False
            self.seen = now
        return True


def add_clutter(frame, rig: Rig, rng: np.random.Generator, kinds: tuple[str, ...], count: int,
                scale: tuple[float, float], protect: set[tuple[int, int]] | None = None,
                random_materials: bool = False, tries: int = 6) -> int:  # fmt: skip
    """Add up to ``count`` occluders of ``kinds`` to ``frame.room``; returns how many were added."""
    if count == 0 or not frame.persons:
        return 0
    place = Placement(frame, rig, protect)
    pelvis = np.array([(p.points[F["left_hip"]] + p.points[F["right_hip"]])[:2] / 2 for p in frame.persons])
    cams = place.cams
    added = 0
    for _ in range(count):
        kind = str(kinds[rng.integers(len(kinds))])
        for _ in range(tries):
            person = frame.persons[rng.integers(len(frame.persons))]
            v = int(rng.integers(len(rig)))
            target = person.points[F["neck"]] * 0.4 + person.points[F["left_hip"]] * 0.3
            target = target + person.points[F["right_hip"]] * 0.3 + np.append(rng.uniform(-350, 350, 2), 0)
            pos = cams[v] + rng.uniform(0.15, 0.8) * (target - cams[v])
            to_cam = cams[v] - pos
            yaw = float(np.arctan2(to_cam[1], to_cam[0]) + rng.normal(0, 0.3))
            mat = _random_material(rng) if random_materials and rng.random() < 0.5 else None
            prims = occluder(kind, pos, yaw, float(rng.uniform(*scale)), place.ceiling, rng, mat)
            if kind in FLOOR_KINDS and np.linalg.norm(pelvis - pos[:2], axis=1).min() < 400:
                continue
            if not place.fits(prims, hangs=kind in ("panel", "lamp", "column", "boom")):
                continue
            if not place.add(prims):
                continue
            added += 1
            break
    return added


def _keeps_box(
    before: int, after: int, unoccluded: int, min_pixels: int = 350, fraction: float = 0.12
) -> bool:
    """Whether a person who had ``before`` visible pixels keeps a safe margin over the box rule with ``after``
    (see :class:`~posenet.synth.scene.VisibilityConfig`)."""
    need = max(min_pixels, fraction * unoccluded)
    return after >= before or (after >= 0.75 * before and after >= 2 * need)
