"""The cross-view matcher on hand-made scenes with exactly known geometry."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from pipeline.matching import (
    box_centres_3d,
    box_depths,
    choose_greedily,
    choose_optimally,
    combinations_within,
    match_boxes,
    valid_combinations,
)
from posenet.cameras import Camera

W, H = 320, 240


def ring_cameras(n: int, radius: float = 3000.0, height: float = 0.0) -> list[Camera]:
    """n cameras on a circle of ``radius`` mm around a scene centre, ``height`` mm above it, looking at it.

    Extrinsics are T(v->0): camera 0 is the reference (identity). The scene centre lies ``radius`` mm in
    front of camera 0 (and ``height`` mm below it).
    """
    centre = np.array([0.0, 0.0, radius])
    poses = []
    for i in range(n):
        a = 2 * np.pi * i / n
        yaw = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        pos = centre + yaw @ np.array([0.0, 0.0, -radius]) + np.array([0.0, -height, 0.0])  # -y is up
        f = (centre - pos) / np.linalg.norm(centre - pos)
        x = np.cross([0.0, 1.0, 0.0], f)
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = np.stack([x, np.cross(f, x), f], axis=1), pos  # columns: camera axes
        poses.append(T)
    to_ref = np.linalg.inv(poses[0])
    return [Camera.create(250.0, 250.0, (W - 1) / 2, (H - 1) / 2, to_ref @ T, size=(W, H)) for T in poses]


def render(cams: list[Camera], people: np.ndarray, visible=None, background: int = 0, min_seen: float = 0.0):
    """Boxes and depth images of ``people (P, 3)`` (mm, reference frame), each a 500 x 1700 mm upright slab.

    ``visible[v]`` lists the people drawn in view v; a box is kept only where at least ``min_seen`` of its
    pixels show that person (0 keeps boxes of hidden people too).
    Returns per view (boxes (K, 4), depth (H, W) uint16, ids (K,)).
    """
    out = []
    for v, cam in enumerate(cams):
        ids = list(range(len(people))) if visible is None else list(visible[v])
        cam_pts = cam.to_camera(torch.as_tensor(people, dtype=torch.float64)).numpy()  # (P, 3)
        depth = np.full((H, W), background, np.uint16)
        boxes = []
        # Paint far to near so nearer people occlude farther ones, as in a real depth image.
        for p in sorted(ids, key=lambda p: -cam_pts[p, 2]):
            x, y, z = cam_pts[p]
            u, vv = 250.0 * x / z + (W - 1) / 2, 250.0 * y / z + (H - 1) / 2
            hw, hh = 250.0 * 250 / z, 250.0 * 850 / z
            box = np.array([u - hw, vv - hh, u + hw, vv + hh])
            x0, y0 = max(int(np.ceil(box[0])), 0), max(int(np.ceil(box[1])), 0)
            x1, y1 = min(int(np.floor(box[2])), W - 1), min(int(np.floor(box[3])), H - 1)
            depth[y0 : y1 + 1, x0 : x1 + 1] = round(z)
            boxes.append((p, box, (y0, y1, x0, x1), round(z)))
        if min_seen > 0:
            seen = [(depth[a : b + 1, c : d + 1] == z).mean() if b >= a and d >= c else 0.0
                    for _, _, (a, b, c, d), z in boxes]  # fmt: skip
            boxes = [pb for pb, f in zip(boxes, seen, strict=True) if f >= min_seen]
        boxes = sorted((p, box) for p, box, _, _ in boxes)
        out.append(
            (
                np.array([b for _, b in boxes], np.float32).reshape(-1, 4),
                depth,
                np.array([p for p, _ in boxes], np.int64),
            )
        )
    return out


def groups_as_people(groups, views):
    """Each group as the set of (view, person id) it holds."""
    return sorted(
        tuple(sorted((v, int(views[v][2][i])) for v, i in enumerate(g.indices) if i >= 0)) for g in groups
    )


def test_three_views_two_people():
    cams = ring_cameras(3)
    people = np.array([[-600.0, 0.0, 3000.0], [700.0, 0.0, 3300.0]])
    views = render(cams, people)
    groups = match_boxes([b for b, _, _ in views], [d for _, d, _ in views], cams)
    assert groups_as_people(groups, views) == [
        ((0, 0), (1, 0), (2, 0)),
        ((0, 1), (1, 1), (2, 1)),
    ]
    for g in groups:
        assert g.size == 3 and 0 <= g.mean_distance < 750
        # The slab is 0 mm thick, so every view's centre lifts onto the person's own vertical axis.
        assert np.min(np.linalg.norm(people - g.centre, axis=1)) < 300


def test_person_seen_once_and_stacked_cameras():
    cams = ring_cameras(3)
    people = np.array([[0.0, 0.0, 3000.0], [1200.0, 0.0, 2500.0]])
    views = render(cams, people, visible=[[0, 1], [0], [0]])
    boxes, depths = [b for b, _, _ in views], [d for _, d, _ in views]
    groups = match_boxes(boxes, depths, cams)
    assert groups_as_people(groups, views) == [((0, 0), (1, 0), (2, 0)), ((0, 1),)]
    single = [g for g in groups if g.size == 1][0]
    assert single.indices == (1, -1, -1) and single.mean_distance == 0.0
    # A stacked camera gives the same groups as the list of cameras.
    stacked = match_boxes(boxes, depths, Camera.stack(cams))
    assert [g.indices for g in stacked] == [g.indices for g in groups]


def test_threshold_edge_75cm():
    """Two single-view boxes whose centres lie 740 mm / 760 mm apart match / do not match at t = 750 mm."""
    cams = ring_cameras(2, radius=3000.0)
    for gap, expect in ((740.0, 1), (760.0, 2)):
        # Person A seen only by view 0, person B only by view 1: their centres are exactly `gap` apart in 3D.
        people = np.array([[0.0, 0.0, 3000.0], [gap, 0.0, 3000.0]])
        views = render(cams, people, visible=[[0], [1]])
        centres, _ = box_centres_3d([b for b, _, _ in views], [d for _, d, _ in views], cams)
        assert np.linalg.norm(centres[0] - centres[1]) == pytest.approx(gap, abs=2.0)
        groups = match_boxes([b for b, _, _ in views], [d for _, d, _ in views], cams, threshold_mm=750.0)
        assert len(groups) == expect


def test_empty_view_and_no_boxes():
    cams = ring_cameras(3)
    people = np.array([[0.0, 0.0, 3000.0]])
    views = render(cams, people, visible=[[0], [], [0]])
    groups = match_boxes([b for b, _, _ in views], [d for _, d, _ in views], cams)
    assert [g.indices for g in groups] == [(0, -1, 0)]
    none = match_boxes([np.zeros((0, 4))] * 3, [d for _, d, _ in views], cams)
    assert none == []


def test_box_without_depth_stays_single():
    cams = ring_cameras(2)
    views = render(cams, np.array([[0.0, 0.0, 3000.0]]))
    depths = [views[0][1], np.zeros_like(views[1][1])]  # view 1's sensor saw nothing
    groups = match_boxes([b for b, _, _ in views], depths, cams)
    assert sorted(g.indices for g in groups) == [(-1, 0), (0, -1)]
    assert np.isnan(box_depths(views[1][0], depths[1])).all()


def test_robust_depth_ignores_holes_and_background():
    depth = np.full((100, 100), 5000, np.uint16)
    depth[20:80, 30:70] = 2000  # the person
    depth[45:55, 45:55] = 0  # a hole at the centre pixel
    box = np.array([[20.0, 10.0, 80.0, 90.0]])  # wider than the person: the box edges see the wall
    assert box_depths(box, depth)[0] == 2000


def brute_force_valid(centres, view, t):
    """Every combination of >= 2 boxes from distinct views, all pairs within t (NumPy loops, the
    reference)."""
    out = set()
    n = len(centres)
    for m in range(2, len(set(view.tolist())) + 1):
        for combo in itertools.combinations(range(n), m):
            if len({view[i] for i in combo}) < m:
                continue
            d = [np.linalg.norm(centres[i] - centres[j]) for i, j in itertools.combinations(combo, 2)]
            if max(d) <= t:
                out.add((combo, round(float(np.mean(d)), 6)))
    return out


def test_valid_combinations_equal_brute_force():
    rng = np.random.default_rng(0)
    view = np.repeat(np.arange(4), [3, 2, 4, 3])
    centres = rng.uniform(0, 1500, (len(view), 3))
    centres[5] = np.nan  # a box without depth never matches
    fast = {
        (tuple(int(i) for i in row), round(float(d), 6))
        for members, mean in valid_combinations(centres, view, 800.0)
        for row, d in zip(members, mean, strict=True)
    }
    assert fast == brute_force_valid(centres, view, 800.0)
    assert len(fast) > 10  # the scene is crowded enough to test something


def test_greedy_prefers_larger_then_closer():
    """A 3-view combination beats a closer 2-view one; among 2-view ones the closest wins."""
    cams = ring_cameras(3)
    people = np.array([[0.0, 0.0, 3000.0]])
    views = render(cams, people)
    centres, view = box_centres_3d([b for b, _, _ in views], [d for _, d, _ in views], cams)
    combos = valid_combinations(centres, view, 750.0)
    assert [m.shape[1] for m, _ in combos] == [2, 3]
    groups = match_boxes([b for b, _, _ in views], [d for _, d, _ in views], cams)
    assert len(groups) == 1 and groups[0].size == 3


def _partition_cost(chosen, reward):
    return sum(len(m) * (len(m) - 1) / 2 * (mean - reward) for m, mean in chosen)  # over grouped pairs


def test_optimal_partition_gives_back_the_neighbour_s_box():
    """Person a has boxes 0, 2, 4 (views 0, 1, 2), person b boxes 1, 3 (views 0, 1). The closest triple (0, 3,
    4) takes b's box: greedy then leaves a's and b's other boxes alone; the optimal partition groups a and b."""
    view = np.array([0, 0, 1, 1, 2])
    d = np.full((5, 5), np.inf)
    for (i, j), v in {(0, 2): 320, (0, 4): 280, (2, 4): 300, (1, 3): 100, (0, 3): 250, (3, 4): 240,
                      (1, 2): 900, (1, 4): 900}.items():  # fmt: skip
        d[i, j] = d[j, i] = v
    combos = combinations_within(d, view, 600.0)
    greedy = [tuple(m) for m, _ in choose_greedily(combos, 5)]
    assert greedy == [(0, 3, 4), (1,), (2,)]
    best = choose_optimally(combos, 5, 600.0)
    assert [tuple(m) for m, _ in best] == [(0, 2, 4), (1, 3)]
    assert _partition_cost(best, 600.0) < _partition_cost(choose_greedily(combos, 5), 600.0)


def test_optimal_partition_keeps_a_whole_person_against_two_closer_pairs():
    """Boxes 0, 1, 2 (views 0, 1, 2) are one person, pairwise 200 / 500 / 500; box 3 (view 0) is another person's
    whose skeleton lies 450 from box 2. Counting pairs (3 in the triple), the triple wins; counting links (2 in
    the triple, 2 in two pairs) the pairs (0, 1) and (2, 3) would, splitting the person and merging box 3."""
    view = np.array([0, 1, 2, 0])
    d = np.full((4, 4), np.inf)
    for (i, j), v in {(0, 1): 200, (0, 2): 500, (1, 2): 500, (2, 3): 450}.items():
        d[i, j] = d[j, i] = v
    best = choose_optimally(combinations_within(d, view, 600.0), 4, 600.0)
    assert [tuple(m) for m, _ in best] == [(0, 1, 2), (3,)]


def test_optimal_partition_is_a_partition_and_never_worse_than_greedy(monkeypatch):
    import pipeline.matching

    rng = np.random.default_rng(1)
    for _ in range(30):
        view = np.sort(rng.integers(0, 4, rng.integers(1, 12)))
        pts = rng.uniform(0, 2500, (len(view), 3))
        d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
        combos = combinations_within(d, view, 700.0)
        for reward in (300.0, 700.0, 1e5):
            best = choose_optimally(combos, len(view), reward)
            items = np.sort(np.concatenate([m for m, _ in best]))
            np.testing.assert_array_equal(items, np.arange(len(view)))  # every box exactly once
            for m, _ in best:
                assert len(set(view[m])) == len(m)  # one box per view
            greedy = choose_greedily(combos, len(view))
            assert _partition_cost(best, reward) <= _partition_cost(greedy, reward) + 1e-6
            # the subset search and the integer program find partitions of the same cost
            monkeypatch.setattr(pipeline.matching, "_SEARCH_ITEMS", 0)
            by_milp = choose_optimally(combos, len(view), reward)
            monkeypatch.undo()
            assert abs(_partition_cost(by_milp, reward) - _partition_cost(best, reward)) < 1e-6
            # a search stopped by its state budget hands the component to the integer program
            monkeypatch.setattr(pipeline.matching, "_SEARCH_STATES", 1)
            capped = choose_optimally(combos, len(view), reward)
            monkeypatch.undo()
            assert abs(_partition_cost(capped, reward) - _partition_cost(best, reward)) < 1e-6
        # a huge reward: as few persons as any partition, so never more than greedy's
        assert len(choose_optimally(combos, len(view), 1e5)) <= len(choose_greedily(combos, len(view)))


def test_bad_input_raises():
    cams = ring_cameras(2)
    with pytest.raises(ValueError, match="box lists"):
        match_boxes([np.zeros((0, 4))] * 3, [np.zeros((H, W), np.uint16)] * 3, cams)
    with pytest.raises(ValueError, match="depth"):
        box_depths(np.zeros((1, 4)), np.zeros((2, 3, 4)))


def test_association_counts_found_split_merged():
    from pipeline.association import frame_association

    cams = ring_cameras(3)
    people = np.array([[-600.0, 0.0, 3000.0], [700.0, 0.0, 3300.0]])
    views = render(cams, people)
    boxes = [b.astype(np.float64) for b, _, _ in views]
    ids = [i for _, _, i in views]
    groups = match_boxes(boxes, [d for _, d, _ in views], cams)
    out = frame_association(boxes, ids, boxes, groups)
    assert (out["found"], out["complete"], out["split"], out["merged"], out["missed"]) == (2, 2, 0, 0, 0)
    assert out["iou_sum"] == pytest.approx(2.0)  # every person: IoU 1 in all 3 views

    from pipeline.matching import Group

    c = np.zeros(3)
    # Person 0 split over two groups; person 1 found.
    split = [Group((0, 0, -1), c, 0.0), Group((-1, -1, 0), c, 0.0), Group((1, 1, 1), c, 0.0)]
    out = frame_association(boxes, ids, boxes, split)
    assert (out["split"], out["found"], out["complete"], out["merged"]) == (1, 1, 1, 0)
    # Person 1's box in view 2 not detected: found, but not complete.
    partial = [boxes[0], boxes[1], boxes[2][:1]]
    groups = match_boxes(partial, [d for _, d, _ in views], cams)
    out = frame_association(boxes, ids, partial, groups)
    assert (out["found"], out["complete"]) == (2, 1)
    # Person 0 seen in views 0 and 1, person 1 in view 2 only, all three boxes in one group -> both merged.
    seen = render(cams, people, visible=[[0], [0], [1]])
    b2, ids2 = [b.astype(np.float64) for b, _, _ in seen], [i for _, _, i in seen]
    out = frame_association(b2, ids2, b2, [Group((0, 0, 0), c, 0.0)])
    assert (out["merged"], out["found"], out["split"]) == (2, 0, 0)
    # A box in no group (an unsure box that completed nobody) is not a detection: person 1's box in view 2 is
    # left out of every group, so person 1 is found but not complete, not split.
    unowned = [Group((0, 0, 0), c, 0.0), Group((1, 1, -1), c, 0.0)]
    out = frame_association(boxes, ids, boxes, unowned)
    assert (out["found"], out["complete"], out["split"]) == (2, 1, 0)
    assert out["nobody"] == 0
    # A box far from every annotated box, alone in its group: a person that is nobody
    far = [np.concatenate([b, [[0.0, 0.0, 5.0, 5.0]]]) for b in boxes]
    out = frame_association(boxes, ids, far, [*groups, Group((2, -1, -1), c, 0.0)])
    assert (out["found"], out["groups"], out["nobody"]) == (2, 3, 1)
    # Nothing detected -> both missed; the paper's score is 0.
    empty = [np.zeros((0, 4))] * 3
    out = frame_association(boxes, ids, empty, [])
    assert out["missed"] == 2 and out["iou_sum"] == 0.0


def test_dense_components_equal_scipy():
    from scipy.sparse.csgraph import connected_components

    from pipeline.matching import components

    rng = np.random.default_rng(0)
    for n in (0, 1, 2, 7, 30, 300):  # 300: beyond a frame, the sparse search itself
        for density in (0.0, 0.05, 0.3):
            a = rng.random((n, n)) < density
            a |= a.T
            expected = connected_components(a, directed=False)[1] if n else np.zeros(0)
            np.testing.assert_array_equal(components(a), expected)
