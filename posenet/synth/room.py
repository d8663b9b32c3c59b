"""The operating room: shell (floor, walls, ceiling), operating table, draped patient and mobile equipment.

World frame: z up, the floor at z = 0, mm. The table's long axis is its local x. Equipment that occludes
people is drawn from the kinds found in an OR: ceiling lamps and monitors on booms, C-arm-like shapes,
carts, an anaesthesia machine, IV poles and drape screens. :func:`sample_room` places it at random, keeping
the floor-standing pieces away from the people (``keep_clear``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posenet.synth.primitives import OWNER_ROOM, Material, Primitive, box, capsule, ellipsoid, shell

WALLS = np.array([[0.55, 0.62, 0.60], [0.60, 0.65, 0.70], [0.70, 0.72, 0.70], [0.45, 0.55, 0.55]])
FLOORS = np.array([[0.30, 0.33, 0.32], [0.40, 0.42, 0.45], [0.25, 0.32, 0.30], [0.45, 0.45, 0.42]])
DRAPES = np.array([[0.10, 0.30, 0.50], [0.12, 0.40, 0.35], [0.20, 0.45, 0.60], [0.08, 0.25, 0.20]])
METAL = Material((0.55, 0.57, 0.60), ir_dropout=0.25, texture=0.02, specular=0.6)
WHITE_PAINT = Material((0.80, 0.80, 0.78), texture=0.02, specular=0.2)
DARK = Material((0.04, 0.04, 0.05), ir_dropout=0.35, texture=0.01, specular=0.3)  # screens, table pad
GREY = Material((0.35, 0.36, 0.38), texture=0.03)


@dataclass
class Room:
    """A sampled room.

    Attributes:
        primitives: everything static (shell, floor, table, equipment), owner OWNER_ROOM or OWNER_SHELL.
        table_center: (3,) centre of the table top surface.
        table_yaw: the table's long axis angle about z (radians).
        table_size: (length, width) of the top, mm.
        half_extent: (3,) the shell's half sizes; its centre is at (0, 0, height / 2).
    """

    primitives: list[Primitive] = field(default_factory=list)
    table_center: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 950.0]))
    table_yaw: float = 0.0
    table_size: tuple[float, float] = (2000.0, 550.0)
    half_extent: np.ndarray = field(default_factory=lambda: np.array([4000.0, 3500.0, 1500.0]))

    def table_axes(self) -> tuple[np.ndarray, np.ndarray]:
        c, s = np.cos(self.table_yaw), np.sin(self.table_yaw)
        return np.array([c, s, 0.0]), np.array([-s, c, 0.0])


def yaw_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _mat(rgb: np.ndarray, rng: np.random.Generator, **kw) -> Material:
    return Material(tuple(float(c) for c in np.clip(rgb * rng.uniform(0.9, 1.1, 3), 0, 1)), **kw)


def room_shell(rng: np.random.Generator, center_xy: np.ndarray, half_extent: np.ndarray) -> list[Primitive]:
    """Walls/ceiling (the inside of a box) and a floor slab (so that the floor has its own colour)."""
    hx, hy, hz = half_extent
    walls = shell([center_xy[0], center_xy[1], hz], half_extent, _mat(WALLS[rng.integers(len(WALLS))], rng))
    floor_mat = _mat(FLOORS[rng.integers(len(FLOORS))], rng, texture=0.06, specular=0.1)
    floor = box(
        [center_xy[0], center_xy[1], -20.0], [hx - 1, hy - 1, 20.0], owner=OWNER_ROOM, material=floor_mat
    )
    return [walls, floor]


def table(center: np.ndarray, yaw: float, size: tuple[float, float]) -> list[Primitive]:
    """An operating table: dark padded top, column and base. ``center`` is the top surface's centre."""
    R = yaw_matrix(yaw)
    L, W = size
    top_z = center[2]
    prims = [
        box(center - [0, 0, 45], [L / 2, W / 2, 45], R, material=DARK),
        box([center[0], center[1], top_z / 2], [200, 130, top_z / 2 - 90], R, material=WHITE_PAINT),
        box([center[0], center[1], 60], [420, 280, 60], R, material=WHITE_PAINT),
    ]
    return prims


def drape_over(
    center: np.ndarray, yaw: float, length: float, width: float, height: float, material: Material, owner: int
) -> Primitive:
    """A drape: a box lying over a patient, hanging ``height`` mm down the table's sides."""
    R = yaw_matrix(yaw)
    return box(center, [length / 2, width / 2, height / 2], R, owner=owner, material=material)


# ------------------------------------------------------------------ equipment


def ceiling_lamp(pos: np.ndarray, ceiling: float, rng: np.random.Generator) -> list[Primitive]:
    r = rng.uniform(280, 400)
    tilt = yaw_matrix(rng.uniform(0, 2 * np.pi)) @ _tilt(rng.uniform(0, 0.5))
    mount = np.array([pos[0] + rng.uniform(-500, 500), pos[1] + rng.uniform(-500, 500), ceiling])
    return [
        capsule(mount, pos + [0, 0, 120], 35, material=WHITE_PAINT),
        ellipsoid(pos, [r, r, 90], tilt, material=WHITE_PAINT),
    ]


def _tilt(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def boom_monitor(pos: np.ndarray, yaw: float, ceiling: float, size=(600.0, 400.0)) -> list[Primitive]:
    """A flat screen (dark face, grey back) hanging from a ceiling boom."""
    R = yaw_matrix(yaw)
    w, h = size
    return [
        capsule([pos[0], pos[1], ceiling], pos + [0, 0, h / 2], 40, material=WHITE_PAINT),
        box(pos, [35, w / 2, h / 2], R, material=DARK),
    ]


def c_arm(pos: np.ndarray, yaw: float) -> list[Primitive]:
    """A mobile C-arm: base cart, column and a C made of capsules."""
    R = yaw_matrix(yaw)
    prims = [box(pos + [0, 0, 450], [450, 300, 450], R, material=WHITE_PAINT)]
    centre = pos + R @ np.array([700.0, 0, 1100])
    ang = np.linspace(-0.5 * np.pi, 0.9 * np.pi, 8)  # an open arc in the vertical plane of the local x axis
    radius = 450.0
    arc = [centre + R @ np.array([radius * np.cos(a), 0, radius * np.sin(a)]) for a in ang]
    prims += [capsule(arc[i], arc[i + 1], 70, material=WHITE_PAINT) for i in range(len(arc) - 1)]
    prims.append(
        capsule(
            pos + R @ np.array([300.0, 0, 900]),
            centre + R @ np.array([-radius, 0, 0]),
            80,
            material=WHITE_PAINT,
        )
    )
    prims.append(ellipsoid(arc[0], [200, 200, 120], R, material=GREY))  # detector
    return prims


def cart(pos: np.ndarray, yaw: float, rng: np.random.Generator) -> list[Primitive]:
    R = yaw_matrix(yaw)
    h = rng.uniform(800, 1300)
    half = [rng.uniform(250, 400), rng.uniform(200, 300), h / 2]
    mat = METAL if rng.random() < 0.5 else WHITE_PAINT
    prims = [box(pos + [0, 0, h / 2 + 80], half, R, material=mat)]
    if rng.random() < 0.5:  # a monitor on top
        prims.append(box(pos + [0, 0, h + 80 + 200], [30, 250, 180], R, material=DARK))
    return prims


def anaesthesia_machine(pos: np.ndarray, yaw: float) -> list[Primitive]:
    R = yaw_matrix(yaw)
    return [
        box(pos + [0, 0, 750], [350, 400, 700], R, material=GREY),
        box(pos + R @ np.array([0.0, 0, 700]) + [0, 0, 900], [40, 300, 220], R, material=DARK),
    ]


def iv_pole(pos: np.ndarray) -> list[Primitive]:
    return [
        capsule(pos + [0, 0, 50], pos + [0, 0, 2000], 15, material=METAL),
        ellipsoid(pos + [0, 80, 1800], [60, 30, 110], material=Material((0.8, 0.85, 0.9), texture=0.01)),
    ]


def screen(pos: np.ndarray, yaw: float, rng: np.random.Generator, size=(900.0, 1800.0)) -> list[Primitive]:
    """A mobile drape screen / lead shield on the floor."""
    R = yaw_matrix(yaw)
    w, h = size
    mat = _mat(DRAPES[rng.integers(len(DRAPES))], rng, texture=0.05)
    return [box(pos + [0, 0, h / 2 + 100], [25, w / 2, h / 2], R, material=mat)]


def sample_room(
    rng: np.random.Generator,
    keep_clear: np.ndarray | None = None,
    n_equipment: int | None = None,
    table_center: np.ndarray | None = None,
    table_yaw: float | None = None,
    enclose: np.ndarray | None = None,
    table_size: tuple[float, float] | None = None,
) -> Room:
    """A random room around a table at the origin (or at ``table_center``).

    ``keep_clear (N, 2)`` are floor positions (people) that floor-standing equipment must keep 600 mm away
    from; ``enclose (K, 3)`` are points (cameras) that the shell must contain.
    """
    tc = (
        np.array([0.0, 0.0, rng.uniform(880, 1020)])
        if table_center is None
        else np.asarray(table_center, float)
    )
    yaw = rng.uniform(-0.1, 0.1) if table_yaw is None else float(table_yaw)
    size = (rng.uniform(1900, 2150), rng.uniform(520, 600)) if table_size is None else table_size
    half = np.array([rng.uniform(3300, 4500), rng.uniform(3000, 4000), rng.uniform(1450, 1600)])
    if enclose is not None and len(enclose):
        need = np.abs(np.asarray(enclose, float)[:, :2] - tc[:2]).max(0) + 250
        half[:2] = np.maximum(half[:2], need)
        half[2] = max(half[2], float(np.max(enclose[:, 2])) / 2 + 120)
    room = Room(table_center=tc, table_yaw=yaw, table_size=size, half_extent=half)
    room.primitives += room_shell(rng, tc[:2], half)
    room.primitives += table(tc, yaw, size)
    ceiling = 2 * half[2]
    clear = np.zeros((0, 2)) if keep_clear is None else np.asarray(keep_clear, float).reshape(-1, 2)

    def free_spot(min_r: float, max_r: float) -> np.ndarray | None:
        for _ in range(20):
            a = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(min_r, max_r)
            p = tc[:2] + r * np.array([np.cos(a), np.sin(a)])
            if len(clear) == 0 or np.linalg.norm(clear - p, axis=1).min() > 600:
                return np.array([p[0], p[1], 0.0])
        return None

    for _ in range(rng.integers(1, 3)):  # lamps above the table
        p = np.array([*(tc[:2] + rng.uniform(-700, 700, 2)), rng.uniform(1900, 2250)])
        room.primitives += ceiling_lamp(p, ceiling, rng)
    n = int(rng.integers(3, 7)) if n_equipment is None else n_equipment
    kinds = rng.choice(
        ["monitor", "c_arm", "cart", "anaesthesia", "iv", "screen"],
        size=n,
        p=[0.25, 0.12, 0.28, 0.1, 0.13, 0.12],
    )
    for kind in kinds:
        face = rng.uniform(0, 2 * np.pi)
        if kind == "monitor":
            p = np.array([*(tc[:2] + rng.uniform(-1500, 1500, 2)), rng.uniform(1650, 2050)])
            room.primitives += boom_monitor(p, face, ceiling, (rng.uniform(450, 750), rng.uniform(300, 480)))
            continue
        spot = free_spot(900, 2600)
        if spot is None:
            continue
        to_table = np.arctan2(*(tc[:2] - spot[:2])[::-1])
        if kind == "c_arm":
            room.primitives += c_arm(spot, to_table)
        elif kind == "cart":
            room.primitives += cart(spot, face, rng)
        elif kind == "anaesthesia":
            room.primitives += anaesthesia_machine(spot, to_table)
        elif kind == "iv":
            room.primitives += iv_pole(spot)
        else:
            room.primitives += screen(spot, to_table, rng)
    return room


def patient_drape(
    room: Room, rng: np.random.Generator, owner: int
) -> tuple[list[Primitive], list[Primitive]]:
    """The drape over a patient on ``room``'s table, from the chest to beyond the feet.

    Returns ``(sheet, hump)``: the sheet lying on the table and hanging down its sides (room furniture),
    and the rounded hump of the body under it, which belongs to the patient's silhouette (``owner``).
    """
    ax, _ = room.table_axes()
    L, W = room.table_size
    length = L * rng.uniform(0.72, 0.82)
    centre = room.table_center + ax * (L / 2 - length / 2 + 60)
    mat = _mat(DRAPES[rng.integers(len(DRAPES))], rng, texture=0.06)
    hang = rng.uniform(200, 320)
    sheet = drape_over(
        centre + [0, 0, (25 - hang) / 2],
        room.table_yaw,
        length,
        W + rng.uniform(60, 140),
        hang + 25,
        mat,
        OWNER_ROOM,
    )
    R = yaw_matrix(room.table_yaw)
    hump = ellipsoid(centre + [0, 0, 20], [length / 2 - 40, W / 2 - 40, rng.uniform(150, 210)], R, owner, mat)
    return [sheet], [hump]
