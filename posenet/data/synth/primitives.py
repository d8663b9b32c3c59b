"""Analytic primitives (ellipsoid, capsule, oriented box, room shell) and their ray intersections.

Everything that the renderer draws is one of these shapes, so a frame is a short list of primitives and a
view is rendered by solving one small quadratic (or slab test) per primitive on the pixels of its screen
rectangle only. Units are mm. A :class:`Primitive` lives in the world (room) frame;
:meth:`Primitive.to_camera`
moves it into an OpenCV camera frame (see ``posenet.cameras``), where the ray through pixel (u, v) is
``t * ((u - cx) / fx, (v - cy) / fy, 1)``: the ray parameter ``t`` *is* the depth along z.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

ELLIPSOID, CAPSULE, BOX, SHELL = 0, 1, 2, 3

# Owner ids below zero are not persons (persons are 0, 1, 2, ...).
OWNER_ROOM = -1  # furniture and equipment
OWNER_SHELL = -2  # floor, walls, ceiling


@dataclass(frozen=True)
class Material:
    """Surface appearance.

    Attributes:
        albedo: (3,) linear RGB reflectance in [0, 1].
        ir_dropout: probability that the depth sensor returns nothing on this surface (dark, shiny, metal).
        texture: amplitude of the multiplicative fabric/grain noise.
        specular: strength of the Blinn-Phong highlight (metal and screens shine, cloth does not).
    """

    albedo: tuple[float, float, float]
    ir_dropout: float = 0.0
    texture: float = 0.04
    specular: float = 0.0


@dataclass(frozen=True)
class Primitive:
    """One shape.

    Attributes:
        kind: ELLIPSOID, CAPSULE, BOX or SHELL.
        center: (3,) centre (ellipsoid, box, shell), or the capsule's midpoint.
        rotation: (3, 3) columns are the shape's local axes (ellipsoid, box, shell).
        size: (3,) ellipsoid radii, box/shell half-extents, or (radius, 0, 0) for a capsule.
        a, b: (3,) capsule segment end points (unused for other kinds).
        owner: person index (>= 0), OWNER_ROOM or OWNER_SHELL.
        material: its :class:`Material`.
    """

    kind: int
    center: np.ndarray
    rotation: np.ndarray
    size: np.ndarray
    owner: int
    material: Material
    a: np.ndarray | None = None
    b: np.ndarray | None = None

    def to_camera(self, T: np.ndarray) -> Primitive:
        """The same primitive in a camera frame; ``T (4, 4)`` maps world points to camera points."""
        R, t = T[:3, :3], T[:3, 3]
        a = None if self.a is None else R @ self.a + t
        b = None if self.b is None else R @ self.b + t
        return replace(self, center=R @ self.center + t, rotation=R @ self.rotation, a=a, b=b)

    def bounding_spheres(self) -> list[tuple[np.ndarray, float]]:
        """Spheres (centre, radius) whose union contains the shape, for the screen rectangle."""
        if self.kind == CAPSULE:
            return [(self.a, float(self.size[0])), (self.b, float(self.size[0]))]
        if self.kind == ELLIPSOID:
            return [(self.center, float(self.size.max()))]
        return [(self.center, float(np.linalg.norm(self.size)))]


def ellipsoid(center, radii, rotation=None, owner=OWNER_ROOM, material=None) -> Primitive:
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return Primitive(ELLIPSOID, np.asarray(center, float), rot, np.asarray(radii, float), owner, material)


def capsule(a, b, radius, owner=OWNER_ROOM, material=None) -> Primitive:
    a, b = np.asarray(a, float), np.asarray(b, float)
    size = np.array([radius, 0.0, 0.0])
    return Primitive(CAPSULE, (a + b) / 2, np.eye(3), size, owner, material, a, b)


def box(center, half_sizes, rotation=None, owner=OWNER_ROOM, material=None) -> Primitive:
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return Primitive(BOX, np.asarray(center, float), rot, np.asarray(half_sizes, float), owner, material)


def shell(center, half_sizes, material=None) -> Primitive:
    """The room seen from inside: an axis-aligned box whose inner faces are floor, walls and ceiling."""
    return Primitive(
        SHELL, np.asarray(center, float), np.eye(3), np.asarray(half_sizes, float), OWNER_SHELL, material
    )


# ------------------------------------------------------------------ intersections
# Each function takes the ray directions of a pixel rectangle as three arrays (dx, dy broadcast to (h, w),
# dz = 1) and returns the hit depth t of shape (h, w), np.inf where the ray misses.


def _local_dirs(M: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> list[np.ndarray]:
    """Rows of ``M (3, 3)`` applied to the directions (dx, dy, 1): three (h, w) arrays."""
    return [M[i, 0] * dx + M[i, 1] * dy + M[i, 2] for i in range(3)]


def hit_ellipsoid(p: Primitive, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    M = p.rotation.T / p.size[:, None]  # world -> unit-sphere coordinates
    o = -(M @ p.center)  # the camera centre in unit-sphere coordinates
    d = _local_dirs(M, dx, dy)
    a = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    b = d[0] * o[0] + d[1] * o[1] + d[2] * o[2]
    c = float(o @ o) - 1.0
    h = b * b - a * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(h)) / a
    return np.where(h >= 0, t, np.inf)


def _hit_sphere(center: np.ndarray, r: float, dx, dy, dd) -> np.ndarray:
    b = -(dx * center[0] + dy * center[1] + center[2])
    c = float(center @ center) - r * r
    h = b * b - dd * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(h)) / dd
    return np.where(h >= 0, t, np.inf)


def hit_capsule(p: Primitive, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    r = float(p.size[0])
    dd = dx * dx + dy * dy + 1.0
    ba = p.b - p.a
    oa = -p.a
    baba, baoa, oaoa = float(ba @ ba), float(ba @ oa), float(oa @ oa)
    bard = ba[0] * dx + ba[1] * dy + ba[2]
    rdoa = oa[0] * dx + oa[1] * dy + oa[2]
    A = baba * dd - bard * bard
    B = baba * rdoa - baoa * bard
    C = baba * oaoa - baoa * baoa - r * r * baba
    h = B * B - A * C
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-B - np.sqrt(h)) / A
    y = baoa + t * bard  # position along the axis, in units of |ba|
    body = np.where((h >= 0) & (y > 0) & (y < baba), t, np.inf)
    caps = np.minimum(_hit_sphere(p.a, r, dx, dy, dd), _hit_sphere(p.b, r, dx, dy, dd))
    return np.minimum(body, caps)


def _slabs(p: Primitive, dx, dy) -> tuple[np.ndarray, np.ndarray]:
    Rt = p.rotation.T
    o = -(Rt @ p.center)
    d = _local_dirs(Rt, dx, dy)
    t_near = np.full(np.broadcast_shapes(dx.shape, dy.shape), -np.inf)
    t_far = np.full_like(t_near, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(3):  # three slabs, not a loop over pixels
            inv = 1.0 / d[i]
            t1 = (-p.size[i] - o[i]) * inv
            t2 = (p.size[i] - o[i]) * inv
            t_near = np.maximum(t_near, np.minimum(t1, t2))
            t_far = np.minimum(t_far, np.maximum(t1, t2))
    return t_near, t_far


def hit_box(p: Primitive, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    t_near, t_far = _slabs(p, dx, dy)
    return np.where((t_near <= t_far) & (t_near > 0), t_near, np.inf)


def hit_shell(p: Primitive, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    _, t_far = _slabs(p, dx, dy)
    return np.where(t_far > 0, t_far, np.inf)


HIT = {ELLIPSOID: hit_ellipsoid, CAPSULE: hit_capsule, BOX: hit_box, SHELL: hit_shell}


def normals(p: Primitive, pts: np.ndarray) -> np.ndarray:
    """Unit outward normals ``(N, 3)`` of primitive ``p`` at surface points ``pts (N, 3)`` (camera frame).

    The shell's normals point into the room, since it is seen from inside.
    """
    c, R, size = (x.astype(np.float32) for x in (p.center, p.rotation, p.size))
    if p.kind == CAPSULE:
        a = p.a.astype(np.float32)
        ba = (p.b - p.a).astype(np.float32)
        s = np.clip((pts - a) @ ba / float(ba @ ba), 0.0, 1.0)
        n = pts - (a + s[:, None] * ba)
    elif p.kind == ELLIPSOID:
        local = (pts - c) @ R / size**2
        n = local @ R.T
    else:
        local = (pts - c) @ R / size
        axis = np.abs(local).argmax(axis=1)
        sign = np.sign(np.take_along_axis(local, axis[:, None], 1))
        if p.kind == SHELL:
            sign = -sign
        n = R.T[axis] * sign
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
