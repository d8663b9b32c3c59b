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

ELLIPSOID, CAPSULE, BOX, SHELL, CONE = 0, 1, 2, 3, 4
MESH = 5  # a triangle mesh (``Primitive.mesh``), rasterised by posenet.synth.mesh_raster

# Owner ids below zero are not persons (persons are 0, 1, 2, ...).
OWNER_ROOM = -1  # furniture and equipment
OWNER_SHELL = -2  # floor, walls, ceiling
# Hard negatives (posenet.synth.hard_negatives): -10, -11, ..., one id per object, so that a view's owner map tells
# them apart; everything else reads them as the room.
OWNER_HARD_NEGATIVE = -10


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
class TriangleMesh:
    """The triangles of a :data:`MESH` primitive: ``vertices (N, 3)`` mm, ``normals (N, 3)`` unit vertex
    normals (interpolated over each triangle), ``faces (F, 3)`` vertex indices, wound counter-clockwise seen
    from outside."""

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray


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
        mesh: the triangles of a MESH primitive (whose ``center`` and ``size[0]`` are a bounding sphere).
    """

    kind: int
    center: np.ndarray
    rotation: np.ndarray
    size: np.ndarray
    owner: int
    material: Material
    a: np.ndarray | None = None
    b: np.ndarray | None = None
    mesh: TriangleMesh | None = None

    def to_camera(self, T: np.ndarray) -> Primitive:
        """The same primitive in a camera frame; ``T (4, 4)`` maps world points to camera points."""
        R, t = T[:3, :3], T[:3, 3]
        if self.mesh is not None:
            m = self.mesh
            moved = TriangleMesh(m.vertices @ R.T.astype(m.vertices.dtype) + t.astype(m.vertices.dtype),
                                 m.normals @ R.T.astype(m.normals.dtype), m.faces)  # fmt: skip
            return replace(self, center=R @ self.center + t, rotation=R @ self.rotation, mesh=moved)
        a = None if self.a is None else R @ self.a + t
        b = None if self.b is None else R @ self.b + t
        return replace(self, center=R @ self.center + t, rotation=R @ self.rotation, a=a, b=b)

    def bounding_spheres(self) -> list[tuple[np.ndarray, float]]:
        """Spheres (centre, radius) whose union contains the shape, for the screen rectangle."""
        if self.kind == CAPSULE:
            return [(self.a, float(self.size[0])), (self.b, float(self.size[0]))]
        if self.kind == CONE:  # the hull of two spheres projects inside the box of their projections
            return [(self.a, float(self.size[0])), (self.b, float(self.size[1]))]
        if self.kind in (ELLIPSOID, MESH):
            return [(self.center, float(self.size.max()))]
        return [(self.center, float(np.linalg.norm(self.size)))]


def ellipsoid(center, radii, rotation=None, owner=OWNER_ROOM, material=None) -> Primitive:
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return Primitive(ELLIPSOID, np.asarray(center, float), rot, np.asarray(radii, float), owner, material)


def capsule(a, b, radius, owner=OWNER_ROOM, material=None) -> Primitive:
    a, b = np.asarray(a, float), np.asarray(b, float)
    size = np.array([radius, 0.0, 0.0])
    return Primitive(CAPSULE, (a + b) / 2, np.eye(3), size, owner, material, a, b)


def round_cone(a, b, radius_a, radius_b, owner=OWNER_ROOM, material=None) -> Primitive:
    """A tapered limb: the convex hull of spheres of ``radius_a`` at ``a`` and ``radius_b`` at ``b``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if np.linalg.norm(b - a) <= abs(radius_a - radius_b):
        raise ValueError(
            f"round cone: one sphere contains the other (|b - a| = {np.linalg.norm(b - a):.1f} mm)"
        )
    size = np.array([radius_a, radius_b, 0.0])
    return Primitive(CONE, (a + b) / 2, np.eye(3), size, owner, material, a, b)


def box(center, half_sizes, rotation=None, owner=OWNER_ROOM, material=None) -> Primitive:
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return Primitive(BOX, np.asarray(center, float), rot, np.asarray(half_sizes, float), owner, material)


def triangle_mesh(vertices, normals, faces, owner=OWNER_ROOM, material=None) -> Primitive:
    """A :data:`MESH` primitive; its bounding sphere is centred on the vertices' bounding box."""
    vertices = np.asarray(vertices)
    lo, hi = vertices.min(0), vertices.max(0)
    center = (lo + hi).astype(float) / 2
    radius = float(np.sqrt(((vertices - center) ** 2).sum(1).max())) + 1.0
    mesh = TriangleMesh(vertices, np.asarray(normals), np.asarray(faces))
    return Primitive(MESH, center, np.eye(3), np.array([radius, 0.0, 0.0]), owner, material, mesh=mesh)


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


def hit_round_cone(p: Primitive, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Inigo Quilez's rounded-cone intersection, on unit ray directions (t is then rescaled to depth)."""
    ra, rb = float(p.size[0]), float(p.size[1])
    inv = 1.0 / np.sqrt(dx * dx + dy * dy + 1.0)  # unit directions: (dx, dy, 1) * inv
    ba = p.b - p.a
    oa, ob = -p.a, -p.b
    rr = ra - rb
    m0, m1, m5, m7 = float(ba @ ba), float(ba @ oa), float(oa @ oa), float(ob @ ob)
    m2 = (ba[0] * dx + ba[1] * dy + ba[2]) * inv
    m3 = (oa[0] * dx + oa[1] * dy + oa[2]) * inv
    m6 = (ob[0] * dx + ob[1] * dy + ob[2]) * inv
    d2 = m0 - rr * rr
    k2 = d2 - m2 * m2
    k1 = d2 * m3 - m1 * m2 + m2 * rr * ra
    k0 = d2 * m5 - m1 * m1 + m1 * rr * ra * 2.0 - m0 * ra * ra
    h = k1 * k1 - k0 * k2
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-np.sqrt(h) - k1) / k2
        y = m1 - ra * rr + t * m2
        body = np.where((h >= 0) & (y > 0) & (y < d2), t, np.inf)
        h1 = m3 * m3 - m5 + ra * ra
        h2 = m6 * m6 - m7 + rb * rb
        cap_a = np.where(h1 > 0, -m3 - np.sqrt(h1), np.inf)
        cap_b = np.where(h2 > 0, -m6 - np.sqrt(h2), np.inf)
    # The cone's side is tangent to both spheres, so the nearest valid hit of the three is the surface.
    return np.minimum(body, np.minimum(cap_a, cap_b)) * inv  # distance along the unit ray to depth


HIT = {ELLIPSOID: hit_ellipsoid, CAPSULE: hit_capsule, BOX: hit_box, SHELL: hit_shell, CONE: hit_round_cone}


def normals(p: Primitive, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Unit outward normals ``(3, N)`` of primitive ``p`` at surface points with coordinates ``x, y, z (N,)``.

    Points are in the camera frame. Column arrays with scalar coefficients keep every operation a contiguous
    1-D pass (much faster in numpy than (N, 3) @ (3, 3) products). The shell's normals point into the room,
    since it is seen from inside.
    """
    if p.kind == CONE:
        return _round_cone_normals(p, x, y, z)
    if p.kind == CAPSULE:
        a, ba = p.a, p.b - p.a
        s = ((x - a[0]) * ba[0] + (y - a[1]) * ba[1] + (z - a[2]) * ba[2]) * (1.0 / float(ba @ ba))
        np.clip(s, 0.0, 1.0, out=s)
        n = [x - a[0] - s * ba[0], y - a[1] - s * ba[1], z - a[2] - s * ba[2]]
    else:
        c, R = p.center, p.rotation
        d = (x - c[0], y - c[1], z - c[2])
        # local coordinates along the shape's axes: local_i = sum_j d_j R[j, i]
        local = [d[0] * R[0, i] + d[1] * R[1, i] + d[2] * R[2, i] for i in range(3)]
        if p.kind == ELLIPSOID:
            g = [local[i] * (1.0 / p.size[i] ** 2) for i in range(3)]
            n = [g[0] * R[j, 0] + g[1] * R[j, 1] + g[2] * R[j, 2] for j in range(3)]
        else:  # box or shell: the normal of the face whose slab the point is most outside of
            q = [np.abs(local[i]) * (1.0 / p.size[i]) for i in range(3)]
            ax0 = (q[0] >= q[1]) & (q[0] >= q[2])
            ax1 = ~ax0 & (q[1] >= q[2])
            ax2 = ~ax0 & ~ax1
            sign = -1.0 if p.kind == SHELL else 1.0
            w = [np.where(m, np.sign(local[i]) * sign, 0.0) for i, m in enumerate((ax0, ax1, ax2))]
            n = [w[0] * R[j, 0] + w[1] * R[j, 1] + w[2] * R[j, 2] for j in range(3)]
    n = np.stack(n).astype(np.float32)  # (3, N)
    return n / np.maximum(np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2), 1e-9)


def _round_cone_normals(p: Primitive, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Normals ``(3, N)`` of a round cone: sphere caps beyond the tangent circles, the tilted side between."""
    ra, rb = float(p.size[0]), float(p.size[1])
    ba = p.b - p.a
    length = float(np.linalg.norm(ba))
    e = ba / length
    sin_a = (ra - rb) / length  # the side's normal leans toward the thin end by this much
    cos_a = np.sqrt(max(1 - sin_a * sin_a, 0.0))
    d = (x - p.a[0], y - p.a[1], z - p.a[2])
    along = d[0] * e[0] + d[1] * e[1] + d[2] * e[2]
    q = [d[i] - along * e[i] for i in range(3)]  # radial part
    qn = np.maximum(np.sqrt(q[0] ** 2 + q[1] ** 2 + q[2] ** 2), 1e-9)
    side = [cos_a * q[i] / qn + sin_a * e[i] for i in range(3)]
    on_a = along < ra * sin_a  # tangent circles sit where the sphere normal has axial part sin_a
    on_b = along > length + rb * sin_a
    n = [np.where(on_a, d[i] / ra, np.where(on_b, (d[i] - ba[i]) / rb, side[i])) for i in range(3)]
    n = np.stack(n).astype(np.float32)
    return n / np.maximum(np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2), 1e-9)
