"""The MVOR twin: every real MVOR frame re-enacted with the real rig and the real 3D poses.

For each of MVOR's multi-view frames, the twin places one body per annotated 3D pose (MVOR's 12 points, legs
completed down to the floor, see :func:`~posenet.synth.skeleton_full.complete_legs`), the operating table
and draped patient of that day where MVOR has a patient box, and a room around them. "Up" and the floor come
from MVOR's ``firstCamToRoomRef`` (room z is up; the floor height is estimated from the upright poses).

The table (and the patient on it) is not annotated in MVOR, so it is fitted per day: the pose (x, y, yaw,
height) of a patient-sized cuboid whose projected boxes best match MVOR's patient boxes (mean IoU, random
search).

Where MVOR has no box for an annotated person in a view, that person must be hidden there, as in the real
images: a boom-mounted monitor is placed on the ray between that camera and the person, sized to cover the
person's silhouette, at the distance (among a few candidates) that least covers people who must stay visible
in any view. Only if every candidate would hide someone else is the person left undrawn in that view
(``Frame.hidden``); :func:`twin_frame` reports how often each remedy was used.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posenet.boxes import box_iou
from posenet.rig import Rig
from posenet.synth.body import sample_outfit
from posenet.synth.boxes import covered, project_boxes
from posenet.synth.bystanders import add_bystanders
from posenet.synth.looks import Look
from posenet.synth.poses import lying_pose
from posenet.synth.primitives import OWNER_ROOM, Material, box, capsule
from posenet.synth.rig import cam_to_world, intrinsics, mvor_rig, world_to_cam
from posenet.synth.room import DARK, Room, ceiling_lamp, patient_drape, room_shell, table, yaw_matrix
from posenet.synth.scene import Frame, Person, silhouettes
from posenet.synth.sensor import sample_lighting
from posenet.synth.skeleton_full import complete_legs, estimate_floor

PATIENT_EXTENT = np.array([1000.0, 380.0])  # half length, half width of the draped patient (mm)
PATIENT_Z = (-160.0, 210.0)  # its bottom and top relative to the table top (drape hangs, body rises)
OCCLUDER_FRACTIONS = (0.3, 0.22, 0.4, 0.15, 0.5, 0.6)  # where along the camera-person ray a monitor may hang
MONITOR_BACK = Material((0.30, 0.30, 0.32), texture=0.02)


@dataclass
class TwinFrameInfo:
    """One MVOR multi-view frame.

    Attributes:
        day, frame: recording day and frame number (from the file names).
        image_ids: per camera index, MVOR's image id.
        poses: (person_id, (12, 4) keypoints3D with flags, role) per annotated 3D pose (camera-0 frame, mm).
        boxes: (cam index, person_id) -> xyxy MVOR boxes of people with an id (a list: MVOR reuses an id
            for two people in a few frames).
        patient_boxes: per camera index, the patient's xyxy box (or None).
        bystander_boxes: (cam index, xyxy) boxes of clinicians without a 3D pose in this frame.
    """

    day: int
    frame: int
    image_ids: list[int]
    poses: list[tuple[int, np.ndarray, str]]
    boxes: dict[tuple[int, int], list[np.ndarray]]
    patient_boxes: list[np.ndarray | None]
    bystander_boxes: list[tuple[int, np.ndarray]] = field(default_factory=list)


@dataclass
class TwinContext:
    rig: Rig
    floor_z: float
    cam0_to_world: np.ndarray  # (4, 4)
    tables: dict[int, tuple[np.ndarray, float]]  # day -> (top centre (3,), yaw)
    frames: list[TwinFrameInfo] = field(default_factory=list)
    table_iou: dict[int, float] = field(default_factory=dict)  # day -> fitted mean IoU to patient boxes
    rooms: dict[int, tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict
    )  # day -> (centre xy, half size)

    def world_points(self, kp: np.ndarray) -> np.ndarray:
        """``(N, 3)`` world points (z up, mm) of MVOR keypoints ``kp (N, >= 3)`` given in camera 0's frame."""
        T = self.cam0_to_world
        return kp[:, :3] @ T[:3, :3].T + T[:3, 3]


def _xyxy(b) -> np.ndarray:
    return np.array([b[0], b[1], b[0] + b[2], b[1] + b[3]], float)


def load_twin(ann: dict) -> TwinContext:
    """Read an MVOR annotation dict into per-frame twin descriptions, the world frame and the fitted
    tables."""
    params = ann["cameras_info"]["camParams"]
    to_room = np.asarray(params["firstCamToRoomRef"], float).reshape(4, 4)
    P = np.array([p["keypoints3D"] for p in ann["annotations3D"]], float).reshape(-1, 12, 4)[..., :3]
    room_pts = P @ to_room[:3, :3].T + to_room[:3, 3]
    floor_z = estimate_floor(room_pts)
    rig = mvor_rig(ann["cameras_info"], floor_z)
    shift = np.eye(4)
    shift[2, 3] = -floor_z
    cam0_to_world = shift @ to_room

    img_to_cam = {}
    for mv in ann["multiview_images"]:
        for im in mv["images"]:
            img_to_cam[im["id"]] = int(im["cam_id"]) - 1
    by_image: dict[int, list[dict]] = {}
    for a in ann["annotations"]:
        by_image.setdefault(a["image_id"], []).append(a)
    poses_by_mv: dict[str, list[dict]] = {}
    for p in ann["annotations3D"]:
        poses_by_mv.setdefault(p["image_ids"], []).append(p)
    frames = []
    for mv in ann["multiview_images"]:
        ims = mv["images"]
        day = int(ims[0]["day_id"])
        frame_no = int(ims[0]["file_name"].rsplit("/", 1)[-1].split(".")[0])
        image_ids = [0] * len(rig)
        boxes, patient = {}, [None] * len(rig)
        roles = {}
        for im in ims:
            v = img_to_cam[im["id"]]
            image_ids[v] = im["id"]
            for a in by_image.get(im["id"], []):
                if a["person_id"] >= 0:
                    boxes.setdefault((v, a["person_id"]), []).append(_xyxy(a["bbox"]))
                    roles[a["person_id"]] = a["person_role"]
                elif a["person_role"] == "patient":
                    patient[v] = _xyxy(a["bbox"])
        poses, listed = [], set()
        for p in poses_by_mv.get(mv["id"], []):
            key = (p["person_id"], tuple(p["keypoints3D"]))
            if key in listed:  # MVOR lists one pose twice in day 1 frame 24: one person, rendered once
                continue
            listed.add(key)
            kp = np.asarray(p["keypoints3D"], float).reshape(12, 4)
            poses.append((p["person_id"], kp, roles.get(p["person_id"], "clinician")))
        posed = {p[0] for p in poses}
        bystanders = [
            (img_to_cam[a["image_id"]], _xyxy(a["bbox"]))
            for im in ims
            for a in by_image.get(im["id"], [])
            if a["person_role"] == "clinician" and a["person_id"] not in posed
        ]
        frames.append(TwinFrameInfo(day, frame_no, image_ids, poses, boxes, patient, bystanders))
    ctx = TwinContext(rig, floor_z, cam0_to_world, {}, frames)
    for day in sorted({f.day for f in frames}):
        obs = [(v, b) for f in frames if f.day == day for v, b in enumerate(f.patient_boxes) if b is not None]
        ctx.tables[day], ctx.table_iou[day] = fit_table(rig, obs, np.random.default_rng(day))
        ctx.rooms[day] = room_bounds(ctx, day)
    return ctx


def room_bounds(ctx: TwinContext, day: int, margin: float = 700.0) -> tuple[np.ndarray, np.ndarray]:
    """Floor centre (2,) and half sizes (3,) of a room holding the cameras, the table and all people of a day.

    The cameras hang on the walls and ceiling; people must stand inside, with ``margin`` mm to spare.
    """
    cams = cam_to_world(ctx.rig)[:, :3, 3]
    pts = [cams, ctx.tables[day][0][None]]
    pts += [ctx.world_points(kp) for f in ctx.frames if f.day == day for _, kp, _ in f.poses]
    pts = np.concatenate(pts)
    lo, hi = pts[:, :2].min(0) - margin, pts[:, :2].max(0) + margin
    return (lo + hi) / 2, np.array([*((hi - lo) / 2), cams[:, 2].max() / 2 + 150])


def _cuboid_corners(centre: np.ndarray, yaw: np.ndarray, top: np.ndarray) -> np.ndarray:
    """(C, 8, 3) corners of the draped-patient cuboid for C candidate (centre xy, yaw, table top z)."""
    sx, sy = np.meshgrid([-1, 1], [-1, 1], indexing="ij")
    local = np.stack([sx.ravel() * PATIENT_EXTENT[0], sy.ravel() * PATIENT_EXTENT[1]], 1)  # (4, 2)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = centre[:, None, 0] + c * local[:, 0] - s * local[:, 1]  # (C, 4)
    y = centre[:, None, 1] + s * local[:, 0] + c * local[:, 1]
    out = []
    for dz in PATIENT_Z:
        out.append(np.stack([x, y, np.broadcast_to(top[:, None] + dz, x.shape)], -1))
    return np.concatenate(out, 1)


def fit_table(
    rig: Rig,
    observations: list[tuple[int, np.ndarray]],
    rng: np.random.Generator,
    rounds: int = 4,
    samples: int = 3000,
) -> tuple[tuple[np.ndarray, float], float]:
    """The table pose ((top centre (3,), yaw), mean IoU) that best explains the patient boxes ``[(view,
    xyxy)]``."""
    if not observations:
        return (np.array([0.0, 1000.0, 950.0]), 0.0), 0.0
    views = np.array([v for v, _ in observations])
    boxes = np.stack([b for _, b in observations])  # (M, 4)
    best = np.array([0.0, 0.0, 0.0, 950.0])  # x, y, yaw, top z
    spread = np.array([2500.0, 2500.0, np.pi, 150.0])
    centre = cam_to_world(rig)[:, :2, 3].mean(0)  # start from the middle of the rig
    best[:2] = centre
    best_score = -1.0
    for _ in range(rounds):
        cand = best + rng.uniform(-1, 1, (samples, 4)) * spread
        cand[0] = best
        corners = _cuboid_corners(cand[:, :2], cand[:, 2], cand[:, 3])
        proj = project_boxes(rig, corners)  # (V, C, 4)
        iou = box_iou(proj[views], boxes[:, None, :])  # (M, C)
        score = iou.mean(0)
        k = int(score.argmax())
        if score[k] > best_score:
            best, best_score = cand[k].copy(), float(score[k])
        spread = spread * 0.35
    return (np.array([best[0], best[1], best[3]]), float(best[2])), best_score


# ------------------------------------------------------------------ occluders


def _monitor_covering(
    rig: Rig, v: int, rect: np.ndarray, z: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera-facing panel at depth ``z`` in camera ``v`` that exactly covers pixel rectangle ``rect``.

    Returns (centre (3,), half sizes (3,), rotation (3, 3)) in the world frame.
    """
    K = intrinsics(rig)[v]
    uc, vc = (rect[0] + rect[2]) / 2, (rect[1] + rect[3]) / 2
    centre_cam = np.array([(uc - K.cx) / K.fx * z, (vc - K.cy) / K.fy * z, z + 30])
    half = np.array([(rect[2] - rect[0]) / 2 / K.fx * z, (rect[3] - rect[1]) / 2 / K.fy * z, 30.0])
    T = cam_to_world(rig)[v]
    return T[:3, :3] @ centre_cam + T[:3, 3], half, T[:3, :3]


def add_occluders(
    frame: Frame,
    rig: Rig,
    must_hide: set[tuple[int, int]],
    must_show: set[tuple[int, int]],
    ceiling: float,
    min_pixels: int = 350,
) -> dict[str, int]:
    """Hide ``must_hide`` (view, person) pairs behind monitors; returns counts of each remedy."""
    stats = {"occluder": 0, "not_drawn": 0, "out_of_view": 0}
    if not must_hide:
        return stats
    sil = silhouettes(frame, rig)
    T = world_to_cam(rig)
    for v, i in sorted(must_hide):
        if (v, i) not in sil or sil[(v, i)][2] < min_pixels:
            stats["out_of_view"] += 1
            continue
        rect, zmin, _ = sil[(v, i)]
        pad = np.array([-1, -1, 1, 1]) * (0.08 * np.array([rect[2] - rect[0], rect[3] - rect[1]] * 2) + 6)
        rect = rect + pad
        best, best_cost = None, np.inf
        for f in OCCLUDER_FRACTIONS:
            z = max(f * zmin, 400.0)
            centre, half, R = _monitor_covering(rig, v, rect, z)
            sx, sy, sz = np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")
            corners = centre + (np.stack([sx.ravel(), sy.ravel(), sz.ravel()], 1) * half) @ R.T  # (8, 3)
            if corners[:, 2].max() > ceiling - 50 or corners[:, 2].min() < 100:
                continue
            proj = project_boxes(rig, corners[None])[:, 0]  # (V, 4)
            cost = 0.0
            for w, q in must_show:  # people who must stay visible: how much would this panel cover them?
                if (w, q) not in sil or (w == v and q == i):
                    continue
                qb, qz, _ = sil[(w, q)]
                depth = (corners @ T[w, :3, :3].T + T[w, :3, 3])[:, 2]
                if depth.min() >= qz or depth.max() <= 0:
                    continue
                cost += covered(proj[w], qb)
            if cost < best_cost:
                best, best_cost = (centre, half, R), cost
        if best is None or best_cost > 0.5:
            frame.hidden.add((v, i))
            stats["not_drawn"] += 1
            continue
        centre, half, R = best
        frame.room.append(box(centre, half, R, owner=OWNER_ROOM, material=DARK))
        top = centre + R[:, 1] * -half[1]
        frame.room.append(
            capsule(top, [top[0], top[1], ceiling], 25, owner=OWNER_ROOM, material=MONITOR_BACK)
        )
        stats["occluder"] += 1
    return stats


# ------------------------------------------------------------------ frames


def assign_boxes(rig: Rig, persons: list[Person], boxes: dict[tuple[int, int], list[np.ndarray]]) -> set:
    """(view, person index) pairs that MVOR shows: each real box goes to one person with its id.

    Normally a person id has at most one box per view. Where MVOR gives two people the same id, each box goes
    to the person whose projected joints fit it best (IoU), so that nobody is shown twice for one box.
    """
    show = set()
    for (v, pid), real in boxes.items():
        cands = [i for i, p in enumerate(persons) if p.person_id == pid]
        if len(cands) <= len(real):
            show |= {(v, i) for i in cands}
            continue
        pts = np.stack([persons[i].points[:12] for i in cands])  # (C, 12, 3)
        proj = project_boxes(rig, pts)[v]  # (C, 4)
        iou = box_iou(proj[:, None, :], np.stack(real)[None])  # (C, boxes)
        for _ in range(len(real)):  # greedy: best remaining (person, box) pair
            c, b = np.unravel_index(np.argmax(iou), iou.shape)
            show.add((v, cands[c]))
            iou[c, :], iou[:, b] = -1, -1
    return show


def twin_frame(
    ctx: TwinContext, info: TwinFrameInfo, rng: np.random.Generator, look: Look | None = None
) -> tuple[Frame, dict[str, int]]:
    """The twin of one MVOR frame, and how its hidden people were hidden.

    ``look`` (None: the twin look) dresses every person before the occluders are fitted to their silhouettes,
    then adds its own occluders, which keep off the people that MVOR shows."""
    persons = []
    for pid, kp, role in info.poses:
        persons.append(Person(complete_legs(ctx.world_points(kp)), sample_outfit(rng), pid,
                              role if role == "patient" else "clinician"))  # fmt: skip
    centre, yaw = ctx.tables[info.day]
    room_xy, half = ctx.rooms[info.day]
    half = half + [*rng.uniform(0, 500, 2), 0]
    room = Room(table_center=centre, table_yaw=yaw, table_size=(2000.0, 560.0), half_extent=half)
    room.primitives += room_shell(rng, room_xy, half)
    room.primitives += table(centre, yaw, room.table_size)
    ceiling = 2 * half[2]
    if rng.random() < 0.5:
        room.primitives += ceiling_lamp(
            np.array([*(centre[:2] + rng.uniform(-400, 400, 2)), 2250.0]), ceiling, rng
        )
    has_patient_pose = any(p.role == "patient" for p in persons)
    if any(b is not None for b in info.patient_boxes) and not has_patient_pose:
        R = yaw_matrix(yaw)
        hips = centre + R[:, 0] * 150 + [0, 0, 110]
        pts = lying_pose(rng) @ R.T + hips
        sheet, hump = patient_drape(room, rng, owner=len(persons))
        persons.append(Person(pts, sample_outfit(rng, "patient"), -1, "patient", hump))
        room.primitives += sheet
    frame = Frame(persons, room.primitives, sample_lighting(rng))
    dress = None if look is None else look.dress
    if dress is not None:
        for person in persons:
            dress(person)
    must_show = assign_boxes(ctx.rig, persons, info.boxes)
    stats_by = add_bystanders(frame, ctx.rig, info.bystander_boxes, must_show, (room_xy, half), rng, dress)
    must_hide = {
        (v, i) for i, p in enumerate(persons) if p.person_id >= 0 for v in range(len(ctx.rig))
    } - must_show
    stats = add_occluders(frame, ctx.rig, must_hide, must_show, ceiling)
    if look is not None:
        stats |= look.finish(frame, ctx.rig, must_show)
    unique_ids(persons[: len(info.poses)])
    return frame, dict(stats, **stats_by)


def unique_ids(persons: list[Person]) -> None:
    """Give each person after the first with an id already taken a fresh id (the frame's largest + 1, ...).

    MVOR gives two different 3D poses one id in three frames (day 3 frames 115 and 185, day 4 frame 38; it lists
    one pose twice in day 1 frame 24, which :func:`load_twin` reads once). Its own boxes cannot say which box is
    whose; the twin's can, since it renders each person, so its files name each person once: every box and 3D
    pose written under an id belongs to one person. Before 2026-12-05 both persons were written with the first
    pose, and reference boxes of the two people were fused as one."""
    taken: set[int] = set()
    fresh = max((p.person_id for p in persons), default=-1) + 1
    for p in persons:
        if p.person_id in taken:
            p.person_id, fresh = fresh, fresh + 1
        taken.add(p.person_id)
