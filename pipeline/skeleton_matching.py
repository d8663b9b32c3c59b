"""Group boxes across views by their single-view 3D skeletons: association that uses the pose network.

The centre matcher (``pipeline.matching``) lifts one depth per box, the median over the box's central region; a
box that is a little off centre lifts it onto a neighbour or the wall, and the person is split or merged. The pose
network already reads every box on its own (``posenet.net.box_poses``), so each box also gives a 3D skeleton from
that view alone, from the depth at the pixels the network believes are the joints. Two boxes of one person in
two views give two skeletons that agree joint by joint, wherever their box centres fall.

The rule, for the N boxes of a frame:

1. **Distance.** Between two boxes, the median over the joints of the distance between their single-view
   skeletons (robust to a few joints lifted onto the wrong surface); NaN when either box had no valid depth.
2. **One person, two boxes in one view** (the detector split or duplicated it): boxes of the same view whose
   skeletons lie within ``same_view_mm`` are one unit. The unit keeps all its boxes: their heatmaps all vote in
   the person's softmax (a duplicate adds little, a split adds the half the other box missed), and the person's
   box in that view is their hull.
3. **Across views.** Units of distinct views are grouped from the combinations whose members are pairwise within
   ``threshold_mm`` (the distance between units: the closest pair of their boxes). By default one partition for
   the whole frame (``pipeline.matching.choose_optimally``): each pair of units grouped together earns
   ``link_reward_mm`` against its distance, and the cheapest set of groups wins, so a close triple cannot take a
   neighbour's box that two better groups need. ``link_reward_mm=None`` is the paper's greedy rule
   (more members first, then the closest). Box centres farther apart than ``centre_gate_mm`` never match: a
   sanity bound, wider than the centre matcher's 75 cm because the centre is what fails.
4. Units left over are persons seen in one view.
5. **Boxes the detector was unsure of** (optional, ``candidate``): a box scored below the detector's threshold
   never starts a person, but it may complete one. After the grouping above, each person without a box in a
   view may take that view's unsure box whose single-view skeleton lies within ``candidate_mm`` of the person's
   fused skeleton (one box per person and view, the closest, by optimal assignment; ByteTrack's second
   association, made across views). On day 4 of the twin, 32 of the 35 annotated boxes that no confident box
   covers are covered by an unsure one (IoU >= 0.5, scores 0.17-0.49): a person half hidden behind another is
   still seen, just not confidently.
6. **A box that disagrees with the rest of its person** (``outlier_mm``): in a person of three or more boxes,
   each box's single-view skeleton is compared with the person fused from its other boxes; the box farthest
   from it is dropped when that median joint distance exceeds ``outlier_mm``. Such a box holds half of the
   person, or two persons, or another person who was grouped in by mistake, and its heatmaps would pull the
   fused joints (on day 4 of the twin, 12 three-view persons with a box at IoU < 0.5 cost +5 cm each).
7. **A person only one view saw, where another view looks without obstruction** (``free_space_mm``): a
   detected person of one view's boxes whose single-view skeleton projects into another view's image with at
   least ``min_visible_joints`` joints in free space there (the depth that view measures at the joint is no
   more than ``free_space_mm`` in front of it: nothing hides the joint), while no box of that view covers the
   projection, is no person: something one view mistook for one (a lamp, a drape, a monitor). A person that
   the other views do not see because something stands in front of them, or because they are outside the
   image, stays. On the long tracking sequence one static object seen by one camera made 190 false person-frames.

8. **Persons the detector was unsure of in every view** (optional, for trackers: :func:`group_unsure`): the
   unsure boxes that completed no person are grouped among themselves by steps 1-4 and 7. They are never
   answered as persons of a frame; a tracker may take one to continue a track it already follows
   (``pipeline.track``: ByteTrack's second association, made in time). On the long tracking sequence, 115 of the
   196 person-frames that no answered person came within 50 cm of had an unsure box over them (IoU >= 0.5),
   most of them people half behind a monitor or at an image's edge.

The skeletons are lifted from the heatmaps that the pose network computes anyway; the grouped boxes are then fused
from those same heatmaps (``BoxHeatmaps.estimate``), so the U-Net runs once per box in either matcher.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

from pipeline.matching import (
    Group,
    _depth_samples,
    _valid_median,
    box_centres_3d,
    choose_greedily,
    choose_optimally,
    combination_bound,
    combinations_within,
    components,
)
from posenet.boxes import box_coverage, iou_xyxy
from posenet.cameras import Camera
from posenet.scene import SceneView

MATCHERS = ("centres", "skeletons")
# Detected boxes scored from this up to the detector's threshold are unsure: they may complete a person seen
# in other views (step 5), never start one. 32 of the 35 annotated boxes of the twin's day 4 that no sure box
# covers are covered by a box scored 0.17-0.49; 0.25 keeps most of them and about 1.5 unsure boxes per view
# that overlap no sure one.
CANDIDATE_SCORE = 0.25


@dataclass
class SkeletonMatchConfig:
    # Two single-view skeletons of one person differ by both views' depth-direction errors (one view alone is
    # 11-15 cm MPJPE, with a tail far above). Chosen on 120 held-out procedural MVOR-rig scenes (random and twin
    # looks, seed 99; never trained on, not the day-4 test): 250-1000 mm swept with the shipped weights and
    # detector, splits fall to 600 mm and merges rise beyond it (docs/detector.md).
    threshold_mm: float = 600.0
    # Box centres farther apart than this never match (the centre matcher's t is 75 cm; it is the centres that
    # fail, so this is only a bound against two far-apart persons whose skeletons agree by chance). 1500 mm until
    # 2026-12-05: a box over a person's upper body lifts its centre onto whatever stands in front, and on the
    # eight tuning sequences (never the day-4 test) 1500 / 2000 / 2500 mm / no bound split 112 / 36 / 34 / 34 of
    # 3,195 persons and merged 134 each (docs/detector.md).
    centre_gate_mm: float = 2500.0
    # Two boxes of one view whose skeletons agree this well read the same person (a duplicate gives the same
    # skeleton to a few cm). Two people can come this close: on the long tracking sequence two clinicians stood
    # 25 cm apart (mean joint distance) for 10 frames and were merged at 250 mm. Chosen again on held-out data
    # (2026-12-03: the procedural seed-99 scenes in both looks, the tuning sequences seeds 1 and 2):
    # 150 / 200 / 250 mm found 76.1 / 76.9 / 76.9 %, 81.1 % in all three, 54.3 / 54.3 / 54.6 %, 71.3 / 70.0 /
    # 68.0 %; merged 3.1 % in all three, 0.8 %, 0.3 %, 2.5 / 3.5 / 5.7 %.
    same_view_mm: float = 200.0
    # None: the paper's greedy order (more views first, then closer). A number (mm): every combination in one
    # order, its mean skeleton distance minus this per view beyond the first (``choose_greedily``).
    member_bonus_mm: float | None = None
    # None: the greedy order above. A number (mm): one partition for the whole frame (``choose_optimally``),
    # each pair of grouped units earning this much against its skeleton distance. Chosen on the held-out
    # procedural scenes (seed 99) and the tuning sequence (2026-12-03): at 600 mm, persons found 70.0 -> 73.1 %
    # (random look), 75.0 -> 75.0 % (twin look), 63.5 -> 63.5 % (sequence), merged 4.6 -> 2.3 % on the random
    # look; 400-500 split more, 800 merges more on the random look (docs/detector.md).
    link_reward_mm: float | None = 600.0
    # A box below the detector's threshold joins a person (step 5) when its single-view skeleton lies within
    # this median joint distance of the person's fused skeleton. None: unsure boxes are never used.
    candidate_mm: float | None = 300.0
    # Step 6: a box of a person of >= 3 boxes whose single-view skeleton lies farther than this (median joint
    # distance) from the person fused from its other boxes is dropped from it. None: never.
    outlier_mm: float | None = 300.0
    # Step 7: a detected person seen in one view only is dropped when another view sees at least
    # min_visible_joints of its single-view joints in free space (measured depth at most this much in front of
    # the joint) and has no box over them. None: never. Chosen on the held-out procedural scenes (seed 99, both
    # looks) and the tuning sequence (2026-12-03): 100 / 200 / 300 mm x 5-8 joints; 300 mm and 6 joints drop 84
    # of the 266 one-view persons that are nobody and none of the 107 that are someone (docs/detector.md).
    free_space_mm: float | None = 300.0
    min_visible_joints: int = 6

    def __post_init__(self) -> None:
        if self.member_bonus_mm is not None and self.link_reward_mm is not None:
            raise ValueError("member_bonus_mm orders the greedy rule, link_reward_mm replaces it: give one")


def skeleton_distances(joints: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Robust distance between every two skeletons: the median over the joints valid in both.

    Args:
        joints: (N, J, 3) mm, reference frame; ok: (N, J) joints with valid depth.

    Returns:
        (N, N) mm, NaN where two skeletons share no valid joint.
    """
    joints, ok = np.asarray(joints, np.float64), np.asarray(ok, bool)
    if joints.ndim != 3 or joints.shape[-1] != 3 or ok.shape != joints.shape[:2]:
        raise ValueError(f"joints must be (N, J, 3) and ok (N, J), got {joints.shape}, {ok.shape}")
    return joint_median_distance(joints[:, None], ok[:, None], joints[None], ok[None])


def joint_median_distance(a: np.ndarray, a_ok: np.ndarray, b: np.ndarray, b_ok: np.ndarray) -> np.ndarray:
    """The median over the joints valid in both of the distance between skeletons ``a (..., J, 3)`` and
    ``b (..., J, 3)`` (broadcast against each other, as their masks ``(..., J)``); NaN where none is valid."""
    d = np.linalg.norm(a - b, axis=-1)  # (..., J)
    d[~(a_ok & b_ok)] = np.nan
    return _valid_median(d.reshape(-1, d.shape[-1])).reshape(d.shape[:-1])


def box_starts(boxes: Sequence[np.ndarray]) -> np.ndarray:
    """``(V + 1,)`` the number of the first box of each view (boxes are numbered in view order), then N."""
    return np.concatenate([[0], np.cumsum([len(np.asarray(b).reshape(-1, 4)) for b in boxes])]).astype(
        np.int64
    )


def _lifted(estimate) -> tuple[np.ndarray, np.ndarray]:
    """A ``JointEstimate``'s joints ``(P, J, 3)`` and which of them are usable ``(P, J)`` (finite, with points)."""
    joints = estimate.joints.float().cpu().numpy()
    return joints, np.isfinite(joints).all(-1) & estimate.has_points.cpu().numpy()[:, None]


def _units(dist: np.ndarray, view: np.ndarray, same_view_mm: float) -> np.ndarray:
    """(N,) unit label of each box: boxes of one view linked by skeletons within ``same_view_mm``."""
    link = (dist <= same_view_mm) & (view[:, None] == view[None, :])  # NaN compares False
    if np.count_nonzero(link) == np.count_nonzero(np.diagonal(link)):  # no two boxes of a view agree: the
        return np.arange(len(view))  # common case, each box its own unit (what the search below gives)
    labels = components(link)
    # Number the units by their first box, so that the boxes' order (view order) is kept.
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(np.argsort(first))
    return order[labels]


def group_skeletons(
    view: np.ndarray,
    joints: np.ndarray,
    ok: np.ndarray,
    centres: np.ndarray,
    num_views: int,
    config: SkeletonMatchConfig | None = None,
    max_combinations: float | None = None,
) -> list[tuple[np.ndarray, float]]:
    """Group N boxes into persons by their skeletons (see the module docstring).

    Args:
        view: (N,) view of each box; joints: (N, J, 3) single-view skeletons, mm, reference frame; ok: (N, J)
            joints with valid depth; centres: (N, 3) 3D box centres, NaN where unknown (they pass the gate).
        max_combinations: refuse (ValueError) frames whose boxes would make more combinations than this.

    Returns:
        Per person ``(members, mean_distance)``: the box numbers (sorted), and the mean distance between its
        views' units (0 for one view). Multi-view persons first (more views, then closer, first; with
        ``member_bonus_mm``, in the order of its key), then the rest in box order.
    """
    config = config or SkeletonMatchConfig()
    view = np.asarray(view, np.int64)
    n = len(view)
    if n == 0:
        return []
    dist = skeleton_distances(joints, ok)  # (N, N)
    gap = np.linalg.norm(centres[:, None] - centres[None, :], axis=-1)  # (N, N), NaN without a centre
    allowed = dist <= config.threshold_mm  # NaN compares False
    allowed &= ~(gap > config.centre_gate_mm)  # NaN passes
    unit = _units(dist, view, config.same_view_mm)  # (N,)
    U = int(unit.max()) + 1
    # Distance between units: their closest allowed pair of boxes (the min over each unit's rows, then columns).
    pair = np.where(allowed, dist, np.inf)
    order = np.argsort(unit, kind="stable")
    first = np.searchsorted(unit[order], np.arange(U))  # every unit holds a box: strictly increasing
    rows = np.minimum.reduceat(pair[order], first, axis=0)  # (U, N)
    unit_dist = np.minimum.reduceat(rows[:, order], first, axis=1)  # (U, U)
    unit_view = np.zeros(U, np.int64)
    unit_view[unit] = view
    if max_combinations is not None:
        bound = combination_bound(unit_dist, unit_view, num_views, config.threshold_mm)
        if bound > max_combinations:
            raise ValueError(
                f"the boxes are too crowded to group across views (up to {bound:.3g} combinations of "
                f"skeletons within {config.threshold_mm:g} mm, more than {max_combinations:g}); give "
                "person_ids with the boxes, or fewer boxes"
            )
    combos = combinations_within(unit_dist, unit_view, config.threshold_mm)
    if config.link_reward_mm is None:
        chosen = choose_greedily(combos, U, config.member_bonus_mm)
    else:
        chosen = choose_optimally(combos, U, config.link_reward_mm)
    group_of = np.empty(U, np.int64)
    for g, (units, _) in enumerate(chosen):  # every unit is in exactly one chosen group
        group_of[units] = g
    box_group = group_of[unit]  # (N,)
    members = [np.flatnonzero(box_group == g) for g in range(len(chosen))]
    return [(m, mean) for m, (_, mean) in zip(members, chosen, strict=True)]


def match_skeletons(
    boxes: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    cameras: Camera | Sequence[Camera],
    joints: np.ndarray,
    ok: np.ndarray,
    config: SkeletonMatchConfig | None = None,
    max_combinations: float | None = None,
    centres: np.ndarray | None = None,
) -> list[Group]:
    """Group the boxes of V views into persons by their single-view skeletons.

    Args:
        boxes: V arrays ``(K_v, 4)`` xyxy pixels; depths, cameras: as ``pipeline.matching.match_boxes``.
        joints: (N, J, 3) the single-view skeleton of each of the N = sum K_v boxes, in view order
            (``BoxHeatmaps.single_view``); ok: (N, J) its joints with valid depth.
        centres: (N, 3) the boxes' ``pipeline.matching.box_centres_3d``, when already known.

    Returns:
        :class:`pipeline.matching.Group` s in :func:`group_skeletons`' order; in a view where a person holds
        several boxes, ``indices`` names the first and ``extra`` the others.
    """
    if centres is None:
        centres = box_centres_3d(boxes, depths, cameras)[0]
    V = len(boxes)
    starts = box_starts(boxes)  # (V + 1,)
    view = np.repeat(np.arange(V), np.diff(starts))  # (N,) each box's view
    local = np.arange(len(view)) - starts[view]
    groups = []
    for members, mean in group_skeletons(view, joints, ok, centres, V, config, max_combinations):
        indices = np.full(V, -1)
        extra = []
        for b in members:  # a handful of boxes per person
            if indices[view[b]] < 0:
                indices[view[b]] = local[b]
            else:
                extra.append((int(view[b]), int(local[b])))
        with np.errstate(invalid="ignore"):
            has = ~np.isnan(centres[members, 0])
            centre = centres[members][has].mean(0) if has.any() else np.full(3, np.nan)
        groups.append(Group(tuple(int(i) for i in indices), centre, mean, tuple(extra)))
    return groups


def members_of(groups: Sequence[Group], boxes: Sequence[np.ndarray]) -> np.ndarray:
    """``(P, S)`` box numbers (view order, as ``BoxHeatmaps``) of each group's boxes, -1 padded."""
    starts = box_starts(boxes)
    rows = [[int(starts[v] + k) for v, k in [*enumerate(g.indices), *g.extra] if k >= 0] for g in groups]
    out = np.full((len(rows), max((len(r) for r in rows), default=0)), -1, np.int64)
    for p, r in enumerate(rows):
        out[p, : len(r)] = r
    return out


def view_members(group: Group) -> list[tuple[int, ...]]:
    """Per view, the indices of ``group``'s boxes there: its box (``indices``), then any ``extra`` ones."""
    out: list[list[int]] = [[] if k < 0 else [int(k)] for k in group.indices]
    for v, k in group.extra:
        out[v].append(int(k))
    return [tuple(m) for m in out]


def split_unsure(
    boxes: Sequence[np.ndarray], scores: Sequence[np.ndarray], threshold: float, duplicate_iou: float = 0.7
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Mark each view's boxes scored below ``threshold`` as unsure (the ``candidate`` of :func:`match_heatmaps`),
    leaving out unsure boxes that overlap a sure box of their view by IoU >= ``duplicate_iou`` (the same person
    found twice: the U-Net need not read it).

    Returns per view the boxes ``(K_v, 4)``, their scores ``(K_v,)`` and the unsure mask ``(K_v,)``, in order."""
    out_boxes, out_scores, candidate = [], [], []
    for b, s in zip(boxes, scores, strict=True):
        b, s = np.asarray(b).reshape(-1, 4), np.asarray(s).reshape(-1)
        unsure = s < threshold
        keep = np.ones(len(s), bool)
        if unsure.any() and (~unsure).any():
            keep[unsure] = iou_xyxy(b[unsure], b[~unsure]).max(1) < duplicate_iou
        out_boxes.append(b[keep])
        out_scores.append(s[keep])
        candidate.append(unsure[keep])
    return out_boxes, out_scores, candidate


def match_heatmaps(
    heat,
    views: Sequence[SceneView],
    boxes: Sequence[np.ndarray],
    config: SkeletonMatchConfig | None = None,
    max_combinations: float | None = None,
    candidate: Sequence[np.ndarray] | None = None,
    detected: bool = False,
    centres: np.ndarray | None = None,
) -> list[Group]:
    """Lift each box of ``heat`` (a ``posenet.net.box_poses.BoxHeatmaps`` of ``boxes``) alone and group the boxes.

    ``detected``: the boxes come from a detector, so a box far from the rest of its person is dropped (step 6),
    and so is a one-view person that another view should have seen (step 7). Boxes a user sent are never dropped
    (on reference boxes without ids step 6 split more persons than it mended: day 4 of the twin, found 94.5 ->
    94.1 %).

    ``candidate``: per view ``(K_v,)`` bool, the boxes the detector was unsure of (below its threshold): they
    are left out of the grouping and may then complete persons (step 5 of the module docstring); those that
    do not stay in no group. Fuse the groups from the same heatmaps with
    ``heat.estimate(members_of(groups, boxes))``. ``centres``: (N, 3) every box's ``box_centres_3d``, when
    already known (:func:`group_unsure` may read them again)."""
    config = config or SkeletonMatchConfig()
    joints, ok = _lifted(heat.single_view())  # (N, J, 3), (N, J)
    depths, cameras = [v.depth for v in views], [v.camera for v in views]
    if candidate is None or not any(np.any(c) for c in candidate):
        groups = match_skeletons(boxes, depths, cameras, joints, ok, config, max_combinations, centres)
    else:
        sure = [~np.asarray(c, bool).reshape(-1) for c in candidate]
        flat = np.concatenate(sure)
        groups = match_skeletons([np.asarray(b).reshape(-1, 4)[k] for b, k in zip(boxes, sure, strict=True)],
                                 depths, cameras, joints[flat], ok[flat], config, max_combinations,
                                 None if centres is None else centres[flat])  # fmt: skip
        groups = _in_full_lists(groups, sure)
        if config.candidate_mm is not None and groups:
            groups = admit_candidates(heat, groups, boxes, candidate, joints, ok, config.candidate_mm)
    if not detected:
        return groups
    groups = drop_outliers(heat, groups, boxes, joints, ok, config.outlier_mm)
    return drop_unseen(groups, views, boxes, joints, ok, config.free_space_mm, config.min_visible_joints)


def _in_full_lists(groups: list[Group], subset: Sequence[np.ndarray]) -> list[Group]:
    """``groups`` of the boxes in ``subset`` (per view a (K_v,) bool mask), with each box numbered by its index in
    its view's full list."""
    index = [np.flatnonzero(k) for k in subset]
    return [
        Group(tuple(int(index[v][k]) if k >= 0 else -1 for v, k in enumerate(g.indices)), g.centre,
              g.mean_distance, tuple((v, int(index[v][k])) for v, k in g.extra))
        for g in groups
    ]  # fmt: skip


def unsure_left(groups: Sequence[Group], candidate: Sequence[np.ndarray] | None) -> list[np.ndarray] | None:
    """Per view ``(K_v,)`` bool, the unsure boxes (``candidate``) that no person of ``groups`` holds; None when
    there are none (then :func:`group_unsure` finds nobody)."""
    if candidate is None:
        return None
    left = [np.asarray(c, bool).reshape(-1).copy() for c in candidate]
    for g in groups:
        for v, k in [*enumerate(g.indices), *g.extra]:
            if k >= 0:
                left[v][k] = False
    return left if any(m.any() for m in left) else None


def group_unsure(
    heat,
    views: Sequence[SceneView],
    boxes: Sequence[np.ndarray],
    groups: Sequence[Group],
    candidate: Sequence[np.ndarray] | None,
    config: SkeletonMatchConfig | None = None,
    max_combinations: float | None = None,
    centres: np.ndarray | None = None,
    reaches=None,
) -> list[Group]:
    """The persons of the unsure boxes that ``groups`` (:func:`match_heatmaps`' persons) left out: step 8 of the
    module docstring. They are grouped as the sure boxes are (steps 1-4) and dropped where another view should
    have seen them (step 7); fuse them with ``heat.estimate(members_of(unsure, boxes))``. ``centres``: as
    :func:`match_heatmaps`'. ``reaches``: a function of their fused joints ``(Q, J, 3)`` giving ``(Q,)`` bool, the
    persons worth finishing (those a tracker could use: ``pipeline.track.reaching``); the others are left out before step 7,
    which costs most (each person's other views checked one by one).

    They are no person of the frame on their own: a tracker may take one to continue a track it already has."""
    left = unsure_left(groups, candidate)
    if left is None:
        return []
    config = config or SkeletonMatchConfig()
    joints, ok = _lifted(heat.single_view())  # (N, J, 3), (N, J)
    flat = np.concatenate(left)
    unsure = match_skeletons(
        [np.asarray(b).reshape(-1, 4)[m] for b, m in zip(boxes, left, strict=True)],
        [v.depth for v in views], [v.camera for v in views], joints[flat], ok[flat], config, max_combinations,
        None if centres is None else centres[flat],
    )  # fmt: skip
    unsure = _in_full_lists(unsure, left)
    if reaches is not None and unsure:
        fused = heat.estimate(members_of(unsure, boxes)).joints.double().numpy()  # as they will be answered
        unsure = [g for g, keep in zip(unsure, np.asarray(reaches(fused), bool), strict=True) if keep]
    return drop_unseen(unsure, views, boxes, joints, ok, config.free_space_mm, config.min_visible_joints)


def drop_outliers(
    heat, groups: list[Group], boxes: Sequence[np.ndarray], joints: np.ndarray, ok: np.ndarray,
    within_mm: float | None, min_boxes: int = 3,
) -> list[Group]:  # fmt: skip
    """Drop from each person of ``min_boxes`` or more boxes the one whose single-view skeleton lies farthest
    from the fusion of the others, when farther than ``within_mm`` (step 6 of the module docstring). The
    dropped box belongs to no person afterwards: use it on detected boxes only.

    Args: as :func:`admit_candidates`; ``within_mm`` None returns ``groups`` unchanged."""
    if within_mm is None or not groups:
        return groups
    members = members_of(groups, boxes)  # (P, S)
    size = (members >= 0).sum(1)
    rows, owner = [], []
    for p in np.flatnonzero(size >= min_boxes):
        m = members[p][members[p] >= 0]
        for k in range(len(m)):
            rows.append(np.concatenate([np.delete(m, k), np.full(members.shape[1] - len(m) + 1, -1)]))
            owner.append((p, int(m[k])))
    if not rows:
        return groups
    rest, rest_ok = _lifted(heat.estimate(np.stack(rows)))  # (R, J, 3): each box's person without it
    b = np.array([n for _, n in owner])
    dist = joint_median_distance(rest, rest_ok, joints[b], ok[b])  # (R,)
    dist[np.isnan(dist)] = -np.inf
    starts = box_starts(boxes)
    drop = {}
    for r, (p, n) in enumerate(owner):
        if dist[r] > within_mm and dist[r] > drop.get(p, (None, -np.inf))[1]:
            drop[p] = (n, dist[r])
    out = list(groups)
    for p, (n, _) in drop.items():
        v = int(np.searchsorted(starts, n, side="right") - 1)
        k = int(n - starts[v])
        g = groups[p]
        indices, extra = list(g.indices), [e for e in g.extra if e != (v, k)]
        if indices[v] == k:  # the view's box: another box of that view, if any, takes its place
            promoted = next((e for e in extra if e[0] == v), None)
            indices[v] = -1 if promoted is None else promoted[1]
            extra = [e for e in extra if e != promoted]
        out[p] = Group(tuple(indices), g.centre, g.mean_distance, tuple(extra))
    return out


def admit_candidates(
    heat,
    groups: list[Group],
    boxes: Sequence[np.ndarray],
    candidate: Sequence[np.ndarray],
    joints: np.ndarray,
    ok: np.ndarray,
    within_mm: float,
) -> list[Group]:
    """Give each person a view it lacks from the unsure boxes there (step 5 of the module docstring).

    Args:
        heat: the ``BoxHeatmaps`` of all ``boxes``; groups: persons of the confident boxes (full indices);
        candidate: per view (K_v,) bool; joints, ok: (N, J, 3) / (N, J) every box's single-view skeleton.
    """
    person, person_ok = _lifted(heat.estimate(members_of(groups, boxes)))  # (P, J, 3), (P, J)
    starts = box_starts(boxes)
    indices = [list(g.indices) for g in groups]
    for v, cand in enumerate(candidate):
        ks = np.flatnonzero(np.asarray(cand, bool).reshape(-1))
        ps = [p for p, ind in enumerate(indices) if ind[v] < 0]
        if not len(ks) or not ps:
            continue
        n = starts[v] + ks  # box numbers
        cost = joint_median_distance(
            person[ps][:, None], person_ok[ps][:, None], joints[n][None], ok[n][None]
        )
        cost = np.where(cost <= within_mm, cost, 1e9)  # NaN compares False
        for r, c in zip(*linear_sum_assignment(cost), strict=True):
            if cost[r, c] < 1e9:
                indices[ps[r]][v] = int(ks[c])
    return [
        Group(tuple(ind), g.centre, g.mean_distance, g.extra) for ind, g in zip(indices, groups, strict=True)
    ]


def seen_from(
    views: Sequence[SceneView], points: np.ndarray, free_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which of ``points (K, 3)`` (mm, reference frame) each of the V ``views`` sees unobstructed.

    Returns ``(seen (V, K), inside (V, K), uv (V, K, 2))``: a point is inside a view when it projects into its image
    in front of the camera, and seen when, moreover, the depth measured there (the median valid depth over 5 x 5
    pixels) is at most ``free_mm`` short of the point's own depth: no surface hides it. Pixels without depth say
    nothing. All views are projected at once (one stacked camera), their depths sampled in one median."""
    cameras = Camera.stack([v.camera for v in views])
    p = torch.as_tensor(np.asarray(points, np.float64).reshape(-1, 3), dtype=cameras.intrinsics.dtype)
    in_camera = cameras.to_camera(p)  # (V, K, 3)
    z = in_camera[..., 2].numpy()  # (V, K)
    uv = cameras.project_camera(in_camera).numpy()  # (V, K, 2)
    hw = np.array([v.depth.shape for v in views], np.float64)  # (V, 2)
    with np.errstate(invalid="ignore"):
        inside = (z > 0) & (uv >= 0).all(-1) & (uv[..., 0] < hw[:, 1:]) & (uv[..., 1] < hw[:, :1])
    seen = np.zeros(z.shape, bool)
    if inside.any():
        samples = []
        for v, view in enumerate(views):
            u, w = uv[v, inside[v], 0], uv[v, inside[v], 1]
            samples.append(
                _depth_samples(np.stack([u - 2.5, w - 2.5, u + 2.5, w + 2.5], 1), view.depth, 1.0, 5)
            )
        measured = _valid_median(np.concatenate(samples))  # one median over every view's points
        seen[inside] = measured >= z[inside] - free_mm  # NaN (no depth) compares False
    return seen, inside, uv


def drop_unseen(
    groups: list[Group], views: Sequence[SceneView], boxes: Sequence[np.ndarray], joints: np.ndarray,
    ok: np.ndarray, free_mm: float | None, min_joints: int, covered: float = 0.5,
) -> list[Group]:  # fmt: skip
    """Drop the persons of one view that another view should have seen (step 7 of the module docstring): at
    least ``min_joints`` of the single-view skeleton's usable joints seen there (:func:`seen_from`) and no box
    of that view covering ``covered`` of the box around the joints' projections. Use on detected boxes only.

    Args: as :func:`admit_candidates`, and the frame's ``views``; ``free_mm`` None returns ``groups``."""
    if free_mm is None:
        return groups
    starts = box_starts(boxes)
    alone = {}  # person: (its view, its box number), for persons of one view
    for p, g in enumerate(groups):
        seen_in = [v for v, k in enumerate(g.indices) if k >= 0]
        if len(seen_in) == 1:
            alone[p] = (seen_in[0], int(starts[seen_in[0]] + g.indices[seen_in[0]]))
    if not alone:
        return groups
    persons = list(alone)
    n = np.array([alone[p][1] for p in persons])
    V, J = len(views), joints.shape[1]
    # every alone person's joints in every view at once (a person's own view is skipped below)
    seen, inside, uv = seen_from(views, joints[n].reshape(-1, 3), free_mm)
    seen, inside = seen.reshape(V, -1, J) & ok[n], inside.reshape(V, -1, J) & ok[n]  # (V, R, J)
    uv = uv.reshape(V, -1, J, 2)
    drop = set()
    for v in range(V):
        view_boxes = np.asarray(boxes[v], np.float64).reshape(-1, 4)
        for r in np.flatnonzero(seen[v].sum(1) >= min_joints):
            p = persons[r]
            if alone[p][0] == v or p in drop:
                continue
            at = uv[v, r][inside[v, r]]
            # the box around the projections (a point-sized one is covered by any box around it)
            region = np.concatenate([at.min(0) - 0.5, at.max(0) + 0.5])
            if not np.any(box_coverage(view_boxes, region) >= covered):
                drop.add(p)
    return [g for p, g in enumerate(groups) if p not in drop]
