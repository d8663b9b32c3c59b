"""Pseudo-labels for the person detector from unlabelled multi-view RGB-D video: what ``detector.adapt`` trains on.

A teacher detector's boxes of one synchronised frame become training boxes by three rules that need no label,
only what the recording gives for free:

- **Cross-view confirmation.** The boxes of the V views are grouped into persons with the paper's 3D box-centre
  matcher (``pipeline.matching``, 75 cm). A confident box (score >= ``high``, the confidence gate) is kept when
  another view or a neighbouring frame of the same camera (IoU >= ``neighbour_iou``) confirms it; a weak box
  (``low`` <= score < ``high``) is kept when it is grouped with a confident box of another view. A box that
  nothing confirms is dropped as a likely false positive.
- **Fill-in from other views.** A person kept in two or more views is lifted to 3D from the depth inside its
  boxes (the pixels within ``person_depth_mm`` of each box's robust depth) and projected into every view where
  it has no box. The points that the view's own depth sees (within ``visible_mm``) give the box of the visible
  pixels, as MVOR's annotators drew it; a teacher box there that overlaps it (IoU >= ``snap_iou``) is taken
  instead, whatever its score. Too few visible points (occluded, or outside the image): no box.
- **Static background.** A camera's static scene is the ``background_quantile`` of each pixel's valid depth
  over the frames of a recording day (:func:`background_depth`): what never moves (the table and its drape,
  lamps, monitors) is there, while people walking in front of it are nearer for most of the day. A box whose
  pixels are less than ``min_foreground`` in front of that background (by ``foreground_mm``) is background. A
  person who stands in one place for more than ``1 - background_quantile`` of the day becomes background there
  too: with 0.9, a tenth of the day.
- **Unsettled views.** A view where the teacher has a box scored from ``unsettled_floor`` up to the gate that no
  rule kept, that no kept box overlaps and that does not lie on the static scene holds someone the rules could
  neither confirm nor reject. Trained on, that person would be taught as background (the adapted detector
  would find fewer people), so ``PseudoBoxes.unsettled`` marks the view and ``detector.adapt`` leaves it out of
  that round.

Boxes are xyxy pixels of the depth images given (``posenet.boxes``); depth uint16 mm, 0 unknown; cameras as
``posenet.cameras`` (T(v->0), the reference frame is camera 0's).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from pipeline.matching import box_depths, match_boxes
from posenet.boxes import iou_xyxy
from posenet.cameras import Camera


@dataclass
class PseudoBoxConfig:
    high: float = 0.5  # the confidence gate: a box this sure stands on its own once something confirms it
    certain: float = 0.7  # a box this sure needs no confirmation
    low: float = 0.4  # weaker boxes count as confirmation, and are kept when another view confirms them
    match_mm: float = 750.0  # the paper's box-centre matcher threshold
    neighbour_iou: float = 0.3  # a box in the previous or next frame of the same camera this close confirms
    background_quantile: float = 0.9  # per pixel over a day's frames: the far, static scene
    foreground_mm: float = 150.0  # nearer than the background by this much is foreground
    min_foreground: float = 0.15  # share of a box's valid pixels in front of the background, at least
    # A box on the static scene scoring this much is kept (a clinician who stood still at the table all day
    # looks static; a phantom on the drape scored 0.5-0.6); 1.0: the background drops whatever it holds
    static_certain: float = 0.7
    person_depth_mm: float = 500.0  # a box's pixels within this of its robust depth belong to its person
    visible_mm: float = 150.0  # a projected point is seen when the view's depth agrees within this
    min_visible: float = 0.35  # share of a person's projected points seen, below which no box is filled in
    min_points: int = 20  # seen points a filled-in box needs
    snap_iou: float = 0.4  # a teacher box overlapping a filled-in box this much replaces it
    # A view holding a teacher box scored from this up to the gate that no rule settled (it overlaps no kept box
    # by snap_iou and does not lie on the static scene) is unsettled: trained on, its unkept person would be
    # taught as background, so the adaptation leaves the view out of that round. None (the default): every view
    # is trained on; at 0.1 it did not help on the alt look (docs/detector.md measures both).
    unsettled_floor: float | None = None


@dataclass
class PseudoBoxes:
    """One frame's training boxes and how each came about.

    Attributes:
        boxes: V arrays ``(M_v, 4)`` float32 xyxy pixels.
        counts: ``kept`` (confirmed teacher boxes), ``filled`` (projected from other views), ``snapped`` (a filled
            box replaced by a teacher box below the gate), ``static`` (dropped as background), ``unconfirmed``
            (dropped: no other view, no neighbouring frame), ``unsettled`` (views with a box no rule settled).
        unsettled: V bools: the view holds a teacher box scored from ``unsettled_floor`` up to the gate that
            overlaps no kept box (a person the rules neither kept nor rejected).
    """

    boxes: list[np.ndarray]
    counts: dict[str, int] = field(default_factory=dict)
    unsettled: list[bool] = field(default_factory=list)


def background_depth(depths: np.ndarray, quantile: float = 0.9) -> np.ndarray:
    """The static scene of one camera: ``(H, W)`` float32 mm, the ``quantile`` of each pixel's valid depths over
    ``depths (N, H, W)`` uint16 (NaN where a pixel never had depth)."""
    depths = np.asarray(depths)
    if depths.ndim != 3:
        raise ValueError(f"depths must be (N, H, W), got shape {depths.shape}")
    d = np.where(depths > 0, depths.astype(np.float32), np.nan)
    with warnings.catch_warnings():  # pixels that never had depth are all-NaN slices: expected, NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanquantile(d, quantile, axis=0).astype(np.float32)


def foreground_share(
    boxes: np.ndarray, depth: np.ndarray, background: np.ndarray, margin_mm: float
) -> np.ndarray:
    """``(K,)`` share of each box's valid-depth pixels that lie ``margin_mm`` or more in front of ``background``
    (``(H, W)``, NaN unknown: such pixels do not count). Exact, with integral images."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    if depth.shape != background.shape:
        raise ValueError(f"depth {depth.shape} and background {background.shape} differ")
    d = depth.astype(np.float32)
    valid = (d > 0) & ~np.isnan(background)
    fg = valid & (d < np.nan_to_num(background, nan=0.0) - margin_mm)
    h, w = depth.shape
    x0 = np.clip(np.floor(boxes[:, 0]), 0, w).astype(np.int64)
    y0 = np.clip(np.floor(boxes[:, 1]), 0, h).astype(np.int64)
    x1 = np.clip(np.ceil(boxes[:, 2]) + 1, 0, w).astype(np.int64)
    y1 = np.clip(np.ceil(boxes[:, 3]) + 1, 0, h).astype(np.int64)
    out = []
    for mask in (fg, valid):
        s = np.zeros((h + 1, w + 1), np.int64)
        s[1:, 1:] = mask.cumsum(0).cumsum(1)
        out.append(s[y1, x1] - s[y0, x1] - s[y1, x0] + s[y0, x0])
    return out[0] / np.maximum(out[1], 1)


def confirmed_in_time(boxes: np.ndarray, neighbours: Sequence[np.ndarray], iou: float) -> np.ndarray:
    """``(K,)`` whether each box overlaps a box of a neighbouring frame ``(M_i, 4)`` of the same camera by ``iou``."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    near = np.zeros(len(boxes), bool)
    for other in neighbours:
        other = np.asarray(other, np.float64).reshape(-1, 4)
        if len(boxes) and len(other):
            near |= iou_xyxy(boxes, other).max(1) >= iou
    return near


def person_points(
    boxes: Sequence[np.ndarray | None],
    depths: Sequence[np.ndarray],
    cameras: Camera,
    person_depth_mm: float,
) -> torch.Tensor:
    """``(N, 3)`` reference-frame points (mm) of one person: the valid pixels of each of its boxes (None where it
    has none) within ``person_depth_mm`` of the box's robust depth, lifted with that view's camera."""
    points = []
    for v, box in enumerate(boxes):
        if box is None:
            continue
        depth = depths[v]
        h, w = depth.shape
        centre = box_depths(box[None], depth)[0]
        if np.isnan(centre):
            continue
        x0, y0 = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
        x1, y1 = min(int(np.ceil(box[2])) + 1, w), min(int(np.ceil(box[3])) + 1, h)
        patch = depth[y0:y1, x0:x1].astype(np.float64)  # (h, w) of the box
        vs, us = np.nonzero((patch > 0) & (np.abs(patch - centre) <= person_depth_mm))
        if not len(us):
            continue
        uv = torch.from_numpy(np.stack([us + x0, vs + y0], 1).astype(np.float64))  # (n, 2)
        z = torch.from_numpy(patch[vs, us])
        points.append(cameras[v].to(dtype=torch.float64).unproject(uv, z)[1])  # (n, 3) reference frame
    return torch.cat(points) if points else torch.zeros(0, 3, dtype=torch.float64)


def projected_box(
    points: torch.Tensor, depth: np.ndarray, camera: Camera, cfg: PseudoBoxConfig
) -> np.ndarray | None:
    """The xyxy box ``(4,)`` of the ``points (N, 3)`` that ``camera``'s ``depth (H, W)`` sees, or None when too
    few are seen (occluded, outside the image, or too few points)."""
    if len(points) < cfg.min_points:
        return None
    cam = camera.to(dtype=torch.float64)
    z = cam.to_camera(points)[:, 2]  # (N,)
    uv = cam.project(points).numpy()  # (N, 2)
    h, w = depth.shape
    u, v = np.rint(uv[:, 0]).astype(np.int64), np.rint(uv[:, 1]).astype(np.int64)
    inside = (z.numpy() > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    seen = np.zeros(len(points), bool)
    d = depth[v[inside], u[inside]].astype(np.float64)
    seen[inside] = (d > 0) & (np.abs(d - z.numpy()[inside]) <= cfg.visible_mm)
    if seen.sum() < max(cfg.min_points, cfg.min_visible * len(points)):
        return None
    lo = np.percentile(uv[seen], 1, axis=0)
    hi = np.percentile(uv[seen], 99, axis=0)
    box = np.concatenate([np.clip(lo, 0, [w - 1, h - 1]), np.clip(hi, 0, [w - 1, h - 1])])
    return box if (box[2] - box[0] >= 2 and box[3] - box[1] >= 2) else None


def pseudo_boxes(
    boxes: Sequence[np.ndarray],
    scores: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    cameras: Camera,
    backgrounds: Sequence[np.ndarray] | None,
    neighbours: Sequence[Sequence[np.ndarray]],
    cfg: PseudoBoxConfig,
) -> PseudoBoxes:
    """One frame's training boxes from the teacher's (see the module docstring).

    Args:
        boxes, scores: per view the teacher's ``(K_v, 4)`` xyxy boxes and ``(K_v,)`` scores (at least ``low``, or
            ``unsettled_floor`` when that is lower: boxes below ``low`` only mark their view unsettled).
        depths: per view ``(H, W)`` uint16 mm; ``cameras``: a camera of batch shape ``(V,)`` for those images.
        backgrounds: per view the camera's static depth ``(H, W)`` (:func:`background_depth`), or None.
        neighbours: per view the teacher's boxes ``(M, 4)`` of the neighbouring frames of the same camera.
    """
    V = len(boxes)
    if not (len(scores) == len(depths) == len(neighbours) == V) or cameras.intrinsics.shape[:-1] != (V,):
        raise ValueError(
            f"pseudo_boxes needs one entry per view: {V} box lists, {len(scores)} score lists, {len(depths)} "
            f"depths, {len(neighbours)} neighbour lists, cameras of batch shape {tuple(cameras.intrinsics.shape[:-1])}"
        )
    counts = dict.fromkeys(("kept", "filled", "snapped", "static", "unconfirmed", "unsettled"), 0)
    cand, cand_scores, doubtful = [], [], []
    for v in range(V):
        b = np.asarray(boxes[v], np.float64).reshape(-1, 4)
        s = np.asarray(scores[v], np.float64).reshape(-1)
        # in front of the static scene (one integral image per view serves every box); all, without a background
        front = np.ones(len(b), bool)
        if backgrounds is not None and len(b):
            front = foreground_share(b, depths[v], backgrounds[v], cfg.foreground_mm) >= cfg.min_foreground
        doubt = (
            np.zeros(len(b), bool)
            if cfg.unsettled_floor is None
            else (s >= cfg.unsettled_floor) & (s < cfg.high)
        )
        doubtful.append(b[doubt & front])  # a doubtful box on the static scene is settled, as background
        keep = s >= cfg.low
        b, s, moving = b[keep], s[keep], front[keep]
        if backgrounds is not None and len(b):
            moving = moving | (
                s >= cfg.static_certain
            )  # the detector's own certainty outweighs the background
            counts["static"] += int((~moving & (s >= cfg.high)).sum())
            b, s = b[moving], s[moving]
        cand.append(b)
        cand_scores.append(s)
    groups = match_boxes(cand, depths, cameras, cfg.match_mm)
    kept: list[list[np.ndarray]] = [[] for _ in range(V)]
    persons = []  # per multi-view person: its kept box in each view (None where none)
    for g in groups:
        members = [(v, k) for v, k in enumerate(g.indices) if k >= 0]
        strong = [cand_scores[v][k] >= cfg.high for v, k in members]
        person: list[np.ndarray | None] = [None] * V
        for (v, k), sure in zip(members, strong, strict=True):
            box = cand[v][k]
            if sure:  # another view, or the previous or next frame of this camera, must confirm it
                ok = (
                    cand_scores[v][k] >= cfg.certain
                    or len(members) >= 2
                    or bool(confirmed_in_time(box[None], neighbours[v], cfg.neighbour_iou)[0])
                )
            else:  # below the gate: only a confident box of the same person in another view promotes it
                ok = any(strong)
            if ok:
                person[v] = box
                kept[v].append(box)
                counts["kept"] += 1
            elif sure:
                counts["unconfirmed"] += 1
        if sum(b is not None for b in person) >= 2:
            persons.append(person)
    for person in persons:
        points = None
        for v in range(V):
            if person[v] is not None:
                continue
            if points is None:
                points = person_points(person, depths, cameras, cfg.person_depth_mm)
            box = projected_box(points, depths[v], cameras[v], cfg)
            if box is None:
                continue
            mine = np.asarray(kept[v], np.float64).reshape(-1, 4)
            if len(mine) and iou_xyxy(box[None], mine).max() >= cfg.snap_iou:
                continue  # the view already has this person (the matcher split them)
            if len(cand[v]):
                overlap = iou_xyxy(box[None], cand[v])[0]
                if overlap.max() >= cfg.snap_iou:
                    box = cand[v][int(overlap.argmax())]
                    counts["snapped"] += 1
            kept[v].append(box)
            counts["filled"] += 1
    out = [np.asarray(k, np.float32).reshape(-1, 4) for k in kept]
    unsettled = [  # a doubtful box that no kept box overlaps (with none kept, any doubtful box)
        len(d) > 0
        and (not len(k) or bool((iou_xyxy(d, k.astype(np.float64)).max(axis=1) < cfg.snap_iou).any()))
        for d, k in zip(doubtful, out, strict=True)
    ]
    counts["unsettled"] = sum(unsettled)
    return PseudoBoxes(out, counts, unsettled)
