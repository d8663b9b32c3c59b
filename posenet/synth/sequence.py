"""Rendered sequences: clinicians who walk around the table, work at it, and enter and leave the room.

A :class:`Stage` is one sequence's world: the room, the patient, the look and every person's script over time.
Each person alternates between working at a spot beside the table (postures from :mod:`~.poses` drawn one after
another: bending over it, reaching, raising the arms, turning, standing) and walking to another spot along a path
around the table that swings out behind whoever works there. Some persons enter through a door in the wall after
the start, and some leave through it before the end; outside the room they are not in the frame at all.

Positions, headings and joint angles are scripted piecewise (constant while working, a polyline at walking speed
while walking) and then low-pass filtered over time (Gaussian, a few tenths of a second), so that postures blend
and turns take time; the walking gait (hip, knee and arm swing in phase with the distance walked) is added after
the filter. Everything is drawn from the one generator given to :func:`build_stage`, so a sequence is a pure
function of its seed, and :meth:`Stage.frame` of a frame index is the same in every worker process.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from scipy.ndimage import gaussian_filter1d

from posenet.rig import Rig
from posenet.synth.body import sample_outfit
from posenet.synth.poses import PoseParams, build_pose, lying_pose, place, sample_params
from posenet.synth.rig import cam_to_world
from posenet.synth.room import Room, patient_drape, sample_room
from posenet.synth.scene import Frame, Person
from posenet.synth.sensor import sample_lighting
from posenet.synth.skeleton_full import NUM_MVOR_POINTS

WALK_SPEED = (900.0, 1300.0)  # mm/s, an unhurried walk in a crowded room
STRIDE = 1300.0  # mm walked per gait cycle (two steps)
WORK_SECONDS = (2.5, 6.0)  # time spent at one spot
POSTURE_SECONDS = (1.2, 3.0)  # time one posture is held while working
WORK_POSTURES = ("standing", "bending", "reaching", "arms_raised", "turning")
WORK_WEIGHTS = (0.2, 0.3, 0.25, 0.1, 0.15)
SPOT_OFFSET = (250.0, 400.0)  # mm from the table's edge to a working person's pelvis
PASS_OFFSET = 600.0  # mm further out while walking past the table
SPACING = 700.0  # mm: a spot is chosen this far from where the persons drawn before will be, when it can
SPOT_TRIES = 12
MIN_GAP = 400.0  # mm between two persons' pelvis centres at any time (shoulders may brush when passing)
ENTER_PROB, LEAVE_PROB = 0.35, 0.3  # per person (the first person is there from start to end)
POSITION_SIGMA_S, YAW_SIGMA_S, POSE_SIGMA_S = 0.15, 0.3, 0.3  # temporal low-pass filters
# No joint moves faster than this between frames. A blend of two postures can pass where the elbow's bending
# plane is undefined (the forearm's target along the upper arm), and the forearm then flips; such scripts are
# drawn again.
MAX_JOINT_SPEED = 3000.0  # mm/s
SCRIPT_TRIES = 40


def _params_vector(p: PoseParams) -> np.ndarray:
    """The floats of a :class:`PoseParams`, flattened in field order (tuples contribute two)."""
    out = []
    for f in fields(p):
        v = getattr(p, f.name)
        out += list(v) if isinstance(v, tuple) else [v]
    return np.asarray(out, float)


def _params_from(vector: np.ndarray, like: PoseParams) -> PoseParams:
    """Inverse of :func:`_params_vector`, with ``like``'s layout."""
    kw, i = {}, 0
    for f in fields(like):
        v = getattr(like, f.name)
        n = len(v) if isinstance(v, tuple) else 1
        kw[f.name] = tuple(float(x) for x in vector[i : i + n]) if n > 1 else float(vector[i])
        i += n
    return PoseParams(**kw)


class TableRing:
    """Points at a distance ``d`` from the table's top rectangle, by an angle-like coordinate ``s`` in [0, 1)
    along that curve (two straight sides, two straight ends, four quarter circles), and the heading that faces
    the table from them."""

    def __init__(self, room: Room) -> None:
        self.c = room.table_center[:2]
        self.ax, self.side = (a[:2] for a in room.table_axes())
        self.half = np.array(room.table_size) / 2

    def point(self, s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Floor positions ``(N, 2)`` at ring coordinates ``s (N,)`` and distances ``d (N,)``, and the unit
        normals ``(N, 2)`` that point away from the table there."""
        a = 2 * np.pi * np.asarray(s, float)
        u = np.stack([np.cos(a), np.sin(a)], -1)  # (N, 2) a direction in the table's frame
        # The nearest point of the rectangle to a far point in direction u, then out along the local normal.
        corner = np.clip(u * 1e6, -self.half, self.half)
        out = u * 1e6 - corner
        normal = out / np.linalg.norm(out, axis=-1, keepdims=True)
        local = corner + normal * np.asarray(d, float)[:, None]
        to_world = np.stack([self.ax, self.side], 0)  # (2, 2) rows: table axes in the world
        return self.c + local @ to_world, normal @ to_world


@dataclass
class Script:
    """One person over the whole sequence: per frame, present or not, and the skeleton when present.

    Attributes:
        present: (N,) bool.
        xy: (N, 2) pelvis floor position, mm; yaw: (N,) heading, radians.
        params: per frame, the joint angles (:class:`PoseParams`, gait included).
    """

    present: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    params: list[PoseParams]


def _heading(v: np.ndarray) -> float:
    return float(np.arctan2(v[1], v[0]))


def _draw_script(
    rng: np.random.Generator,
    ring: TableRing,
    door: np.ndarray,
    times: np.ndarray,
    may_come_and_go: bool,
    sector: float,
    others: list[Script],
) -> Script:
    """Draw one person's script over the frame ``times (N,)``, seconds; it starts near ring coordinate
    ``sector`` (persons start spread around the table), and works at spots away from where the ``others``
    (persons drawn before) are."""
    n, end = len(times), float(times[-1]) + 1e-6
    dt = float(times[1] - times[0]) if n > 1 else 1.0
    stature = float(np.clip(rng.normal(1720, 80), 1540, 1960))
    speed = rng.uniform(*WALK_SPEED)
    _, walk_base = sample_params(rng, "standing")
    walk_base.stature = stature
    # Keyframes: (t, xy, yaw or None while walking (heading of travel), params vector, walking?)
    keys: list[tuple[float, np.ndarray, float | None, np.ndarray, bool]] = []
    walk_vec = _params_vector(walk_base)

    def spot(s: float, d: float) -> tuple[np.ndarray, float]:
        p, normal = ring.point(np.array([s]), np.array([d]))
        return p[0], _heading(-normal[0]) + float(rng.normal(0, 0.2))

    def clearance(p: np.ndarray, t0: float) -> float:
        """How close the others come to floor point ``p`` over the next WORK_SECONDS[1] from ``t0``."""
        near = (times >= t0) & (times <= t0 + WORK_SECONDS[1])
        gaps = [np.linalg.norm(o.xy[near & o.present] - p, axis=1) for o in others]
        return min((float(g.min()) for g in gaps if len(g)), default=np.inf)

    def free_spot(t0: float, s_from: float | None) -> tuple[float, float]:
        """A ring coordinate and distance for the next spot (near ``sector`` first, then a step away from
        ``s_from``): the first of SPOT_TRIES draws with SPACING to the others, else the one with the most."""
        best, best_gap = None, -1.0
        for _ in range(SPOT_TRIES):
            if s_from is None:
                cand = ((sector + rng.uniform(-0.08, 0.08)) % 1.0, rng.uniform(*SPOT_OFFSET))
            else:
                step = rng.choice([-1, 1]) * rng.uniform(0.15, 0.45)
                cand = ((s_from + step) % 1.0, rng.uniform(*SPOT_OFFSET))
            gap = clearance(ring.point(np.array([cand[0]]), np.array([cand[1]]))[0][0], t0)
            if gap > best_gap:
                best, best_gap = cand, gap
            if gap >= SPACING:
                break
        return best

    def walk(t: float, path: np.ndarray) -> float:
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        arrive = t + np.concatenate([[0.0], np.cumsum(seg)]) / speed
        keys.extend((float(ta), p, None, walk_vec, True) for ta, p in zip(arrive, path, strict=True))
        return float(arrive[-1])

    t_in = rng.uniform(0, 0.4 * end) if may_come_and_go and rng.random() < ENTER_PROB else None
    t_out = rng.uniform(0.55 * end, 0.9 * end) if may_come_and_go and rng.random() < LEAVE_PROB else None
    s, d = free_spot(t_in or 0.0, None)
    here, face = spot(s, d)
    t = 0.0
    if t_in is not None:  # from the door to the first spot, straight
        t = walk(t_in, np.linspace(door, here, 12))
    while t < (end if t_out is None else t_out):
        stay = rng.uniform(*WORK_SECONDS)
        t_stop = t + stay
        while t < t_stop:  # postures one after another, each held for a while
            posture = str(rng.choice(WORK_POSTURES, p=WORK_WEIGHTS))
            _, params = sample_params(rng, posture)
            params.stature = stature
            keys.append((t, here, face, _params_vector(params), False))
            t += rng.uniform(*POSTURE_SECONDS)
        keys.append((t_stop, here, face, keys[-1][3], False))
        t = t_stop
        # Walk to another spot around the table, the shorter way, swinging out behind the others.
        s_new, d_new = free_spot(t, s)
        ds = (s_new - s + 0.5) % 1.0 - 0.5
        k = max(int(abs(ds) * 60), 4)
        ss = s + ds * np.linspace(0, 1, k)
        dd = np.interp(np.linspace(0, 1, k), [0, 1], [d, d_new]) + PASS_OFFSET * np.sin(
            np.linspace(0, np.pi, k)
        )
        path, _ = ring.point(ss % 1.0, dd)
        t = walk(t, path)
        s, d = s_new, d_new
        here, face = spot(s, d)
    if t_out is not None:
        t = walk(t, np.linspace(here, door, 12))
    # Sample the keyframes at the frame times: positions and params by interpolation, headings from the keys.
    kt = np.array([k[0] for k in keys])
    order = np.argsort(kt, kind="stable")
    keys = [keys[i] for i in order]
    kt = kt[order]
    kxy = np.array([k[1] for k in keys])
    xy = np.stack([np.interp(times, kt, kxy[:, i]) for i in range(2)], -1)  # (N, 2)
    idx = np.clip(np.searchsorted(kt, times, "right") - 1, 0, len(keys) - 1)  # the key in force
    walking = np.array([keys[i][4] for i in idx], float)
    params = np.array([keys[i][3] for i in idx])  # (N, P) held until the next key
    travel = np.gradient(xy, axis=0) if n > 1 else np.zeros_like(xy)  # (N, 2)
    yaw = np.array(
        [_heading(v) if w else keys[i][2] for v, w, i in zip(travel, walking, idx, strict=True)], float
    )
    present = np.ones(n, bool)
    if t_in is not None:
        present &= times >= t_in
    if t_out is not None:
        present &= times <= t
    # Low-pass over time: postures blend, turns take time.
    xy = gaussian_filter1d(xy, POSITION_SIGMA_S / dt, axis=0, mode="nearest")
    yaw = gaussian_filter1d(np.unwrap(yaw), YAW_SIGMA_S / dt, mode="nearest")
    params = gaussian_filter1d(params, POSE_SIGMA_S / dt, axis=0, mode="nearest")
    walking = gaussian_filter1d(walking, POSE_SIGMA_S / dt, mode="nearest")
    # Gait in phase with the distance walked, after the filter.
    phase = (
        2 * np.pi * np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]) / STRIDE
    )
    out = []
    for f in range(n):
        p = _params_from(params[f], walk_base)
        a, sw = walking[f], np.sin(phase[f])
        p.hip_flex = (p.hip_flex[0] + 0.32 * a * sw, p.hip_flex[1] - 0.32 * a * sw)
        knee = 0.55 * a * np.maximum(0.0, -np.sin(phase[f] + np.array([0.6, np.pi + 0.6])))
        p.knee_flex = (p.knee_flex[0] + float(knee[0]), p.knee_flex[1] + float(knee[1]))
        p.shoulder_flex = (p.shoulder_flex[0] - 0.22 * a * sw, p.shoulder_flex[1] + 0.22 * a * sw)
        out.append(p)
    return Script(present, xy, yaw, out)


def _points(sc: Script, k: int) -> np.ndarray:
    """The full skeleton ``(NUM_FULL, 3)`` of a script at frame ``k``."""
    return place(build_pose(sc.params[k]), sc.xy[k], float(sc.yaw[k]))


def _script(rng: np.random.Generator, times: np.ndarray, others: list[Script], **where) -> Script:
    """:func:`_draw_script` (``where``: its ring, door, may_come_and_go and sector), drawn again while some annotated joint moves faster than MAX_JOINT_SPEED or the
    person comes closer than MIN_GAP to one of the ``others`` (walking into someone); after SCRIPT_TRIES draws,
    the smooth draw that keeps the largest gap is kept."""
    limit = MAX_JOINT_SPEED * (float(times[1] - times[0]) if len(times) > 1 else 1.0)
    best, best_gap = None, -1.0
    for _ in range(SCRIPT_TRIES):
        sc = _draw_script(rng, times=times, others=others, **where)
        both = [sc.present & o.present for o in others]
        gap = min((np.linalg.norm(sc.xy[m] - o.xy[m], axis=1).min() for o, m in zip(others, both, strict=True)
                   if m.any()), default=np.inf)  # fmt: skip
        if gap <= best_gap:
            continue  # no better than the best so far: not worth building its poses
        ks = np.flatnonzero(sc.present)
        pts = np.stack([_points(sc, k)[:NUM_MVOR_POINTS] for k in ks])  # (T, 12, 3)
        if len(ks) > 1 and np.linalg.norm(np.diff(pts, axis=0), axis=-1).max() > limit:
            continue
        best, best_gap = sc, gap
        if gap >= MIN_GAP:
            break
    return best if best is not None else sc


@dataclass
class Stage:
    """One sequence's world: the room (with the look's occluders), lighting, look, patient and scripts."""

    room: list
    lighting: object
    look: object | None
    patient: Person | None
    persons: list[Person]  # one per clinician, with its outfit and body; points are set per frame
    scripts: list[Script]

    def frame(self, k: int) -> Frame:
        """The world at frame ``k``: every present clinician (``person_id`` = its index) and the patient."""
        persons = []
        for person, sc in zip(self.persons, self.scripts, strict=True):
            if sc.present[k]:
                pts = _points(sc, k)
                persons.append(Person(pts, person.outfit, person.person_id, person.role, [], person.shape))
        if self.patient is not None:
            p = self.patient
            persons.append(Person(p.points, p.outfit, -1, "patient", p.extra, p.shape))
        return Frame(persons, list(self.room), self.lighting, look=self.look)


def build_stage(
    rng: np.random.Generator,
    rig: Rig,
    frames: int,
    fps: float,
    persons: int,
    look=None,
    patient_prob: float = 0.8,
) -> tuple[Stage, dict]:
    """Draw a sequence of ``frames`` frames at ``fps`` with ``persons`` clinicians seen by ``rig``.

    ``look``: a :class:`~posenet.synth.looks.Look` (None: the twin look), applied once for the whole
    sequence (persons keep their clothes; occluders stay where they are). Returns the stage and the look's stats.
    """
    if frames < 1 or fps <= 0 or persons < 1:
        raise ValueError(f"need frames >= 1, fps > 0 and persons >= 1, got {frames}, {fps}, {persons}")
    times = np.arange(frames) / fps
    probe = sample_room(np.random.default_rng(rng.integers(1 << 62)), n_equipment=0)
    ring = TableRing(probe)
    # Floor equipment keeps clear of the whole walking ring.
    s = np.linspace(0, 1, 48, endpoint=False)
    lanes = np.concatenate([ring.point(s, np.full_like(s, d))[0] for d in (300.0, 750.0)])
    room = sample_room(
        rng,
        keep_clear=lanes,
        table_center=probe.table_center,
        table_yaw=probe.table_yaw,
        enclose=cam_to_world(rig)[:, :3, 3],
        table_size=probe.table_size,
    )
    a = rng.uniform(0, 2 * np.pi)  # the door: inside the wall, on the floor, in a random direction
    u = np.array([np.cos(a), np.sin(a)])
    reach = np.min((room.half_extent[:2] - 350) / np.maximum(np.abs(u), 1e-6))
    door = room.table_center[:2] + u * reach
    scripts: list[Script] = []
    for i in range(persons):  # one after another, each keeping clear of those before
        where = dict(ring=ring, door=door, may_come_and_go=i > 0, sector=i / persons)
        scripts.append(_script(rng, times, list(scripts), **where))
    people = [Person(np.zeros((1, 3)), sample_outfit(rng), i) for i in range(persons)]
    patient = None
    if rng.random() < patient_prob:
        ax, _ = room.table_axes()
        yaw = room.table_yaw
        hips = room.table_center + ax * rng.uniform(-0.05, 0.12) * room.table_size[0] + [0, 0, 110]
        c, sn = np.cos(yaw), np.sin(yaw)
        pts = lying_pose(rng) @ np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]]).T + hips
        sheet, hump = patient_drape(room, rng, owner=persons)
        patient = Person(pts, sample_outfit(rng, "patient"), -1, "patient", hump)
        room.primitives += sheet
    stage = Stage(room.primitives, sample_lighting(rng), None, patient, people, scripts)
    stats: dict = {}
    if look is not None:
        for person in people + ([patient] if patient is not None else []):
            look.dress(person)
        # Occluders are placed once, against the persons in the middle of the sequence; hard negatives also keep
        # clear of everyone's whole walk.
        middle = stage.frame(frames // 2)
        walk = None
        if getattr(look, "hard_negatives", 0):
            walk = np.concatenate([p.points[:, :2] for k in range(frames) for p in stage.frame(k).persons])
        stats = look.finish(middle, rig, keep_clear=walk)
        stage.room, stage.lighting, stage.look = middle.room, middle.lighting, middle.look
    return stage, stats
