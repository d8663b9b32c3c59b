"""Bystanders of the MVOR twin: the clinicians that MVOR boxes but does not pose in 3D.

MVOR has about 1,450 clinician boxes without a 3D pose (most with ``person_id`` -1). They are real people, and
they occlude the annotated ones, so the twin places a procedural standing person where each such box says:
the box's top is taken as the top of a head 1.70 m above the floor (or, when the head is cut by the image
border, its bottom as the feet on the floor), which fixes the person's floor position along that pixel's ray.
Boxes from different views whose positions fall within 70 cm are merged into one person. A bystander is
dropped when it would stand inside someone, outside the room, or in front of more than 40 % of a person who
must stay visible. Each bystander's floor position is then refined (random search within 50 cm) so that its
projected joints, padded by the body's thickness, best fit the boxes it came from. Bystanders get
``person_id`` -1 (box-only, as in MVOR) and are boxed wherever they are visible.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from posenet.boxes import box_iou
from posenet.rig import Rig
from posenet.synth.body import sample_outfit
from posenet.synth.boxes import covered, project_boxes
from posenet.synth.poses import build_pose, place, sample_params
from posenet.synth.rig import cam_to_world, intrinsics
from posenet.synth.scene import Frame, Person, silhouettes
from posenet.synth.skeleton_full import F

HEAD_TOP = 1700.0  # mm above the floor: a standing clinician's cap
MERGE_MM = 700.0
MAX_COVER = 0.4


def floor_position(rig: Rig, v: int, box: np.ndarray) -> np.ndarray | None:
    """Floor position (x, y) of the person boxed by ``box`` (xyxy) in view ``v``, or None if not locatable."""
    K = intrinsics(rig)[v]
    u = (box[0] + box[2]) / 2
    if box[1] > 3:  # the head is in the image: its top is HEAD_TOP above the floor
        row, height = box[1], HEAD_TOP
    elif box[3] < K.height - 4:  # the feet are in the image
        row, height = box[3], 0.0
    else:
        return None
    T = cam_to_world(rig)[v]
    d = T[:3, :3] @ np.array([(u - K.cx) / K.fx, (row - K.cy) / K.fy, 1.0])
    o = T[:3, 3]
    if abs(d[2]) < 1e-6:
        return None
    t = (height - o[2]) / d[2]
    return None if t <= 0 else (o + t * d)[:2]


def merge_positions(
    found: list[tuple[int, np.ndarray, np.ndarray]],
) -> list[tuple[np.ndarray, list[tuple[int, np.ndarray]]]]:
    """Greedy clustering of (view, xy, box): per person its mean xy and its (view, box) members.

    A cluster takes at most one box per view."""
    clusters: list[tuple[set[int], list[np.ndarray], list[tuple[int, np.ndarray]]]] = []
    for v, xy, box in found:
        best, best_d = None, MERGE_MM
        for c in clusters:
            d = float(np.linalg.norm(np.mean(c[1], axis=0) - xy))
            if v not in c[0] and d < best_d:
                best, best_d = c, d
        if best is None:
            clusters.append(({v}, [xy], [(v, box)]))
        else:
            best[0].add(v)
            best[1].append(xy)
            best[2].append((v, box))
    return [(np.mean(c[1], axis=0), c[2]) for c in clusters]


def refine_position(
    rig: Rig, points: np.ndarray, members: list[tuple[int, np.ndarray]], rng: np.random.Generator
) -> np.ndarray:
    """Shift a skeleton ``points (N, 3)`` on the floor so its padded projections best fit its boxes (IoU)."""
    shifts = np.concatenate([np.zeros((1, 2)), rng.uniform(-500, 500, (160, 2))])
    cand = points[None] + np.concatenate([shifts, np.zeros((len(shifts), 1))], 1)[:, None, :]  # (C, N, 3)
    proj = project_boxes(rig, cand)  # (V, C, 4)
    w = proj[..., 2] - proj[..., 0]
    pad = np.stack([-0.25 * w, -0.06 * w, 0.25 * w, 0.0 * w], -1)  # joints sit inside the silhouette
    proj = proj + pad
    score = np.mean([box_iou(proj[v], box) for v, box in members], axis=0)  # (C,)
    return points + [*shifts[int(np.argmax(score))], 0.0]


def add_bystanders(
    frame: Frame,
    rig: Rig,
    boxes: list[tuple[int, np.ndarray]],
    must_show: set[tuple[int, int]],
    room: tuple[np.ndarray, np.ndarray],
    rng: np.random.Generator,
    dress: Callable[[Person], None] | None = None,
) -> dict[str, int]:
    """Append bystanders for ``boxes`` [(view, xyxy)] to ``frame.persons``; returns counts added / dropped.

    ``dress`` (a look's :meth:`~posenet.synth.looks.Look.dress`) re-dresses each new bystander."""
    stats = {"bystanders": 0, "bystanders_dropped": 0}
    found = [(v, xy, b) for v, b in boxes if (xy := floor_position(rig, v, b)) is not None]
    if not found:
        return stats
    room_xy, half = room
    pelvis = [(p.points[F["left_hip"]] + p.points[F["right_hip"]])[:2] / 2 for p in frame.persons]
    first = len(frame.persons)
    for xy, members in merge_positions(found):
        inside = (np.abs(xy - room_xy) < half[:2] - 300).all()
        if not inside or any(np.linalg.norm(xy - q) < 450 for q in pelvis):
            stats["bystanders_dropped"] += 1
            continue
        posture = str(rng.choice(["standing", "arms_crossed", "turning", "reaching"], p=[0.5, 0.2, 0.2, 0.1]))
        _, params = sample_params(rng, posture)
        to_centre = room_xy - xy
        yaw = float(np.arctan2(to_centre[1], to_centre[0]) + rng.normal(0, 0.8))
        points = refine_position(rig, place(build_pose(params), xy, yaw), members, rng)
        xy = (points[F["left_hip"], :2] + points[F["right_hip"], :2]) / 2
        if any(np.linalg.norm(xy - q) < 450 for q in pelvis):
            stats["bystanders_dropped"] += 1
            continue
        frame.persons.append(Person(points, sample_outfit(rng), -1))
        if dress is not None:
            dress(frame.persons[-1])
        pelvis.append(xy)
    if len(frame.persons) == first:
        return stats
    # Drop bystanders that would hide people MVOR shows.
    sil = silhouettes(frame, rig)
    drop = set()
    for b in range(first, len(frame.persons)):
        for v, q in must_show:
            if (v, b) in sil and (v, q) in sil and sil[(v, b)][1] < sil[(v, q)][1]:
                if covered(sil[(v, b)][0], sil[(v, q)][0]) > MAX_COVER:
                    drop.add(b)
                    break
    frame.persons[first:] = [p for k, p in enumerate(frame.persons[first:], first) if k not in drop]
    stats["bystanders"] = len(frame.persons) - first
    stats["bystanders_dropped"] += len(drop)
    return stats
