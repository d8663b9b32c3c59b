"""Procedural frames: clinicians around a table with a draped patient, in a random room.

People stand at the table's sides and ends facing it (mostly bending, reaching or standing), or further back
(standing, turning, arms crossed); some stand close to each other, as in a real team. Everything is drawn from
the generator it is given, so a frame is a pure function of its seed.
"""

from __future__ import annotations

import numpy as np

from posenet.synth.body import sample_outfit
from posenet.synth.poses import build_pose, lying_pose, place, sample_params
from posenet.synth.room import Room, patient_drape, sample_room
from posenet.synth.scene import Frame, Person
from posenet.synth.sensor import sample_lighting

# Clinicians per frame (mean 2.1): MVOR has 1.45 posed people per frame plus ~0.8 box-only clinicians.
CROWD_SIZES = (1, 2, 3, 4, 5)
CROWD_WEIGHTS = (0.30, 0.38, 0.22, 0.08, 0.02)
MIN_SPACING = 480.0  # mm between two people's pelvis centres


def _table_spot(rng: np.random.Generator, room: Room) -> tuple[np.ndarray, float, bool]:
    """A floor position, facing yaw, and whether it is at the table."""
    ax, side = room.table_axes()
    L, W = room.table_size
    c = room.table_center[:2]
    if rng.random() < 0.75:  # at the table: long sides mostly, sometimes the ends
        if rng.random() < 0.8:
            s = rng.choice([-1, 1])
            along = rng.uniform(-L / 2 + 150, L / 2 - 150)
            pos = c + ax[:2] * along + side[:2] * s * (W / 2 + rng.uniform(170, 420))
        else:
            s = rng.choice([-1, 1])
            pos = c + ax[:2] * s * (L / 2 + rng.uniform(200, 450)) + side[:2] * rng.uniform(-300, 300)
        to = c + ax[:2] * np.clip((pos - c) @ ax[:2], -L / 2, L / 2) - pos
        return pos, float(np.arctan2(to[1], to[0]) + rng.normal(0, 0.25)), True
    a = rng.uniform(0, 2 * np.pi)
    pos = c + rng.uniform(1300, 2600) * np.array([np.cos(a), np.sin(a)])
    return pos, float(rng.uniform(0, 2 * np.pi)), False


def procedural_frame(
    rng: np.random.Generator, patient_prob: float = 0.8, enclose: np.ndarray | None = None
) -> Frame:
    """A random frame (world z up, floor at 0): clinicians with person ids 0..N-1, the patient with id -1.

    ``enclose (K, 3)``: points (the cameras) that the room's walls and ceiling must contain.
    """
    n = int(rng.choice(CROWD_SIZES, p=CROWD_WEIGHTS))
    spots: list[tuple[np.ndarray, float, bool]] = []
    room_probe = sample_room(np.random.default_rng(rng.integers(1 << 62)), n_equipment=0)
    # Table geometry is drawn first (equipment must avoid the people, who must stand around the table).
    tries = 0
    while len(spots) < n and tries < 60:
        tries += 1
        pos, yaw, at_table = _table_spot(rng, room_probe)
        if all(np.linalg.norm(pos - p) > MIN_SPACING for p, _, _ in spots):
            spots.append((pos, yaw, at_table))
    room = sample_room(
        rng,
        keep_clear=np.array([p for p, _, _ in spots]).reshape(-1, 2),
        table_center=room_probe.table_center,
        table_yaw=room_probe.table_yaw,
        enclose=enclose,
        table_size=room_probe.table_size,
    )
    persons = []
    for pid, (pos, yaw, at_table) in enumerate(spots):
        posture = None
        if not at_table:
            posture = str(
                rng.choice(["standing", "turning", "arms_crossed", "reaching"], p=[0.45, 0.25, 0.2, 0.1])
            )
        _, params = sample_params(rng, posture)
        pts = place(build_pose(params), pos, yaw)
        persons.append(Person(pts, sample_outfit(rng), pid))
    if rng.random() < patient_prob:
        ax, _ = room.table_axes()
        lying = lying_pose(rng)
        yaw = room.table_yaw
        L = room.table_size[0]
        hips = room.table_center + ax * rng.uniform(-0.05, 0.12) * L + [0, 0, 110]
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        pts = lying @ R.T + hips
        sheet, hump = patient_drape(room, rng, owner=len(persons))
        persons.append(Person(pts, sample_outfit(rng, "patient"), -1, "patient", hump))
        room.primitives += sheet
    return Frame(persons, room.primitives, sample_lighting(rng))
