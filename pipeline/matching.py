"""Group each person's boxes across views: the paper's 3D box-centre matcher, for any number of views.

The paper (section "Bounding Boxes from Detection Transformer"): lift the centre of every box to 3D with the
depth image and the camera, move it to the reference frame, form every combination of boxes from distinct
views, discard a combination when any two of its centres lie more than ``t`` apart (75 cm), then pick
combinations greedily by shortest mean pairwise distance, preferring combinations with more boxes. Unmatched
boxes become single-view persons.

Two choices the paper leaves open:
- **Robust centre depth.** The centre pixel may be a hole (depth 0) or fall between a person's arms onto the
  wall. The depth used is the median of the valid depths on a ``grid x grid`` lattice over the central
  ``central_fraction`` of the box (the torso, for a standing or sitting person). A box with no valid depth
  there has no 3D centre and stays a single-view person.
- **Enumeration.** Instead of forming all prod(K_v) combinations and discarding most, combinations are grown
  one view at a time and pruned at each step (every pair must stay within ``t``). This gives exactly the
  paper's set of valid combinations, vectorised, with work proportional to the number of valid ones: 10 people
  in 4 views is well under a millisecond.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.sparse.csgraph import connected_components

from posenet.cameras import Camera


@dataclass
class Group:
    """One person's boxes across the views.

    Attributes:
        indices: length-V tuple: the index of this person's box in each view's box list, or -1 where it has
        none.
        centre: (3,) mean of the member boxes' 3D centres, mm, reference frame (NaN when no member has depth).
        mean_distance: mean pairwise distance between the member centres, mm (0 for a single box).
        extra: ``(view, index)`` of further boxes of the person in views where it already has one (the skeleton
            matcher merges a person that the detector split or duplicated within a view; the centre matcher
            never does).
    """

    indices: tuple[int, ...]
    centre: np.ndarray
    mean_distance: float
    extra: tuple[tuple[int, int], ...] = ()

    @property
    def size(self) -> int:
        """Number of views in which the person has a box (the paper's "support")."""
        return sum(i >= 0 for i in self.indices)


def _depth_samples(boxes: np.ndarray, depth: np.ndarray, central_fraction: float, grid: int) -> np.ndarray:
    """``(K, grid * grid)`` float depths sampled over each box's central region; NaN where unknown."""
    if depth.ndim != 2:
        raise ValueError(f"depth must be an (H, W) image, got shape {depth.shape}")
    h, w = depth.shape
    t = (np.arange(grid) + 0.5) / grid - 0.5  # (G,) offsets in [-0.5, 0.5] of the region
    cx, cy = (boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2
    bw = (boxes[:, 2] - boxes[:, 0]) * central_fraction
    bh = (boxes[:, 3] - boxes[:, 1]) * central_fraction
    us = np.clip(np.rint(cx[:, None] + bw[:, None] * t), 0, w - 1).astype(np.int64)  # (K, G)
    vs = np.clip(np.rint(cy[:, None] + bh[:, None] * t), 0, h - 1).astype(np.int64)  # (K, G)
    samples = depth[vs[:, :, None], us[:, None, :]].reshape(len(boxes), grid * grid).astype(np.float64)
    samples[samples <= 0] = np.nan
    return samples


def components(link: np.ndarray) -> np.ndarray:
    """``(N,)`` connected-component label of each node of a symmetric boolean adjacency ``(N, N)``, numbered in
    the order of each component's first node (as scipy's ``connected_components``).

    Dense, by squaring the reachability matrix: a frame has tens of boxes, where scipy's conversion to a sparse
    graph costs more than the search (0.21 against 0.05 ms for 15 nodes on a 2-core AMD EPYC)."""
    link = np.asarray(link, bool)
    n = len(link)
    if n == 0:
        return np.zeros(0, np.int64)
    if n > 256:  # beyond a frame's size: the sparse search
        return connected_components(link, directed=False)[1]
    reach = (link | link.T | np.eye(n, dtype=bool)).astype(np.float32)
    while True:
        grown = (reach @ reach > 0).astype(np.float32)
        if np.array_equal(grown, reach):
            break
        reach = grown
    _, labels = np.unique(reach.argmax(1), return_inverse=True)  # each node's smallest reachable node
    return labels.reshape(-1)


def _valid_median(samples: np.ndarray) -> np.ndarray:
    """Row medians ``(K,)`` of ``samples (K, S)`` ignoring NaN (NaN for an all-NaN row).

    A sort (NaN sorts last) and two gathers: numpy's ``nanmedian`` uses masked arrays, 20x slower here.
    """
    s = np.sort(samples, axis=1)
    n = (~np.isnan(s)).sum(axis=1)
    lo = np.take_along_axis(s, np.maximum(n - 1, 0)[:, None] // 2, axis=1)[:, 0]
    hi = np.take_along_axis(s, (n // 2)[:, None], axis=1)[:, 0]
    return np.where(n > 0, (lo + hi) / 2, np.nan)


def box_depths(
    boxes: np.ndarray, depth: np.ndarray, central_fraction: float = 0.5, grid: int = 7
) -> np.ndarray:
    """Robust depth of each box: the median valid depth over its central region.

    Args:
        boxes: (K, 4) xyxy pixels of the depth image.
        depth: (H, W) depth in mm, 0 = unknown.
        central_fraction: side of the sampled region as a fraction of the box side.
        grid: samples per side of the region.

    Returns:
        (K,) float64 depths in mm, NaN where no sample had a valid depth.
    """
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    return _valid_median(_depth_samples(boxes, depth, central_fraction, grid))


def box_centres_3d(
    boxes: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    cameras: Camera | Sequence[Camera],
    central_fraction: float = 0.5,
    grid: int = 7,
) -> tuple[np.ndarray, np.ndarray]:
    """Lift every box centre to the reference frame.

    Returns ``(centres (N, 3), view (N,))`` over the N = sum K_v boxes in view order; rows without depth are
    NaN.
    """
    cams = Camera.stack(list(cameras)) if not isinstance(cameras, Camera) else cameras
    V = len(boxes)
    if cams.intrinsics.shape[:-1] != (V,):
        raise ValueError(f"got {V} box lists but cameras of batch shape {tuple(cams.intrinsics.shape[:-1])}")
    if len(depths) != V:
        raise ValueError(f"got {V} box lists but {len(depths)} depth images")
    boxes = [np.asarray(b, np.float64).reshape(-1, 4) for b in boxes]
    counts = np.array([len(b) for b in boxes])
    kmax = max(int(counts.max(initial=0)), 1)
    uv = np.zeros((V, kmax, 2))
    z = np.full((V, kmax), np.nan)
    # One gather per view (views may differ in size); the work inside is vectorised over boxes and samples.
    samples = []
    for v in range(V):
        uv[v, : counts[v]] = (boxes[v][:, :2] + boxes[v][:, 2:]) / 2
        samples.append(_depth_samples(boxes[v], depths[v], central_fraction, grid))
    valid = np.arange(kmax)[None, :] < counts[:, None]  # (V, kmax)
    z[valid] = _valid_median(np.concatenate(samples))  # one median over all N boxes
    cams = cams.to(dtype=torch.float64)
    _, ref = cams.unproject(torch.from_numpy(uv), torch.from_numpy(np.nan_to_num(z)))  # (V, kmax, 3)
    ref = ref.numpy()
    ref[np.isnan(z)] = np.nan
    view = np.repeat(np.arange(V), counts)
    return ref[valid], view


def valid_combinations(
    centres: np.ndarray, view: np.ndarray, threshold_mm: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """All combinations of >= 2 boxes from distinct views whose centres are pairwise within ``threshold_mm``.

    Args:
        centres: (N, 3) box centres (NaN rows never match); view: (N,) view of each box.

    Returns:
        Per size m = 2, 3, ...: ``(members (P, m), mean_distance (P,))``, members sorted by view.
    """
    dist = np.linalg.norm(centres[:, None] - centres[None, :], axis=-1)  # (N, N), NaN for boxes without depth
    return combinations_within(dist, view, threshold_mm)


def combinations_within(
    dist: np.ndarray, view: np.ndarray, threshold_mm: float
) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`valid_combinations` for any symmetric distance ``dist (N, N)`` between items (NaN never matches)."""
    n = len(dist)
    close = dist <= threshold_mm  # NaN compares False
    close &= view[:, None] < view[None, :]  # one box per view, members in increasing view order
    out = []
    members = np.arange(n)[:, None]  # (P, 1): every box starts a combination
    total = np.zeros(n)  # (P,) sum of pairwise distances so far
    while len(members):
        # A box extends a combination if it is close to every member (and comes from a later view).
        ext = np.logical_and.reduce(close[members], axis=1)  # (P, N)
        p, nxt = np.nonzero(ext)
        if len(p) == 0:
            break
        total = total[p] + dist[members[p], nxt[:, None]].sum(axis=1)
        members = np.concatenate([members[p], nxt[:, None]], axis=1)  # (P', m + 1)
        m = members.shape[1]
        out.append((members, total / (m * (m - 1) / 2)))
    return out


def combination_bound(dist: np.ndarray, view: np.ndarray, num_views: int, threshold_mm: float) -> float:
    """An upper bound on the combinations :func:`combinations_within` enumerates, from the close pairs.

    A combination is grown from its first item b in later views only, each view adding nothing or one item
    close to b; so at most prod over later views v of (1 + items of v close to b) combinations start at b.
    """
    close = dist <= threshold_mm  # NaN compares False
    per_view = close.astype(np.float64) @ np.eye(num_views)[view]  # (N, V) close items in each view
    later = view[:, None] < np.arange(num_views)[None, :]  # (N, V)
    return float(np.prod(np.where(later, 1 + per_view, 1), axis=1).sum())


def choose_greedily(
    combos: list[tuple[np.ndarray, np.ndarray]], n: int, member_bonus: float | None = None
) -> list[tuple[np.ndarray, float]]:
    """The paper's rule: combinations with more members first, then the closest first, each item used once;
    the items left over become single-item groups (in their order). Returns ``(members, mean_distance)``.

    ``member_bonus`` (same unit as the distances) replaces "more members first" by one order over every
    combination: mean distance minus ``member_bonus`` per member beyond the first, lowest first, so that a close
    pair can win over a loose triple that would take a neighbour's item. None: the paper's rule (an infinite
    bonus). The order within a size is the same in both."""
    used = np.zeros(n, bool)
    chosen: list[tuple[np.ndarray, float]] = []
    blocks = list(reversed(combos))  # one (members, mean) block per size, larger first
    if blocks:
        means = np.concatenate([mean for _, mean in blocks])
        block = np.concatenate([np.full(len(mean), b) for b, (_, mean) in enumerate(blocks)])
        row = np.concatenate([np.arange(len(mean)) for _, mean in blocks])
        if member_bonus is None:  # larger combinations first, then the closest first (lexsort is stable)
            ranks = np.lexsort((means, block))
        else:
            size = np.array([members.shape[1] for members, _ in blocks])[block]
            ranks = np.argsort(means - member_bonus * (size - 1), kind="stable")
        for i in ranks:
            members = blocks[block[i]][0][row[i]]
            if not used[members].any():
                used[members] = True
                chosen.append((members, float(means[i])))
    return chosen + [(np.array([b]), 0.0) for b in np.flatnonzero(~used)]


# Components of at most this many items are solved by a memoised search over their subsets, which stops after
# _SEARCH_STATES subsets; larger or harder ones, in crowded frames, by scipy's integer programming (HiGHS:
# 5-15 ms a call). On the twin's day 4 one frame has such a component (14 items, 32 combinations): the search
# solves it in 1.9 ms against 8.7 ms for HiGHS, with the same cost (2-core AMD EPYC, 2026-12-04).
_SEARCH_ITEMS = 40
_SEARCH_STATES = 20_000


class _SearchTooLarge(Exception):
    """The subset search went past ``_SEARCH_STATES``: the integer program solves the component instead."""


def choose_optimally(
    combos: list[tuple[np.ndarray, np.ndarray]], n: int, link_reward: float
) -> list[tuple[np.ndarray, float]]:
    """One partition of the ``n`` items for the whole frame instead of the greedy order: the combinations (each
    item in exactly one, items left alone as single-item groups) that minimise the sum over every pair of items
    grouped together of ``distance - link_reward``. A pair closer than the reward is worth grouping, and a group
    of m items counts its m (m - 1) / 2 pairs, so a whole person seen in three views outweighs two pairs that
    would each be a little closer (a sum over links, m - 1 per group, preferred those two pairs and split the
    person: measured on a rendered sequence), while a triple that holds a neighbour's item loses to the triple
    and the pair that fit better (the greedy rule's failure).

    Solved exactly, per group of items that share combinations: a memoised search over subsets for small
    groups, scipy's ``milp`` for large ones. Returns ``(members, mean_distance)`` in :func:`choose_greedily`'s
    order (more members, then closer, first; then the single items in their order)."""
    blocks = [(members, mean) for members, mean in combos if len(mean)]
    members = [row for m, _ in blocks for row in m]
    means = np.concatenate([mean for _, mean in blocks]) if blocks else np.zeros(0)
    sizes = np.array([len(m) for m in members], np.int64)
    cost = sizes * (sizes - 1) / 2 * (means - link_reward)  # the sum over its pairs of (distance - reward)
    useful = np.flatnonzero(cost < 0)  # a combination that costs more than its items alone is never chosen
    picked: list[int] = []
    if len(useful):
        # Items linked by a useful combination form components that can be solved apart.
        rows = np.concatenate([members[c] for c in useful])
        cols = np.repeat(np.arange(len(useful)), sizes[useful])
        link = np.zeros((n, len(useful)), np.int32)
        link[rows, cols] = 1
        label = components(link @ link.T > 0)  # items sharing a combination
        comp_of = label[[members[c][0] for c in useful]]  # (len(useful),) each combination's component
        for comp in np.unique(comp_of):
            in_comp = [int(c) for c in useful[comp_of == comp]]
            items = np.flatnonzero(label == comp)
            args = ([members[c] for c in in_comp], cost[in_comp], items, in_comp)
            try:
                picked += _search(*args) if len(items) <= _SEARCH_ITEMS else _milp(*args)
            except _SearchTooLarge:
                picked += _milp(*args)
    picked_arr = np.asarray(picked, np.int64)
    picked_arr = picked_arr[np.lexsort((means[picked_arr], -sizes[picked_arr]))]
    chosen = [(np.asarray(members[i]), float(means[i])) for i in picked_arr]
    used = np.zeros(n, bool)
    for m, _ in chosen:
        used[m] = True
    return chosen + [(np.array([b]), 0.0) for b in np.flatnonzero(~used)]


def _search(
    members: list, cost: np.ndarray, items: np.ndarray, ids: list[int], max_states: int | None = None
) -> list[int]:
    """The cheapest set of disjoint combinations over ``items`` (each left alone at cost 0): a memoised search
    over the subsets still to cover, branching on the lowest item. Returns the chosen entries of ``ids``;
    raises ``_SearchTooLarge`` past ``max_states`` subsets (default ``_SEARCH_STATES``)."""
    max_states = _SEARCH_STATES if max_states is None else max_states
    bit = {int(b): 1 << k for k, b in enumerate(items)}
    masks = [sum(bit[int(b)] for b in m) for m in members]
    by_low: dict[int, list[int]] = {}
    for c, mask in enumerate(masks):
        by_low.setdefault(mask & -mask, []).append(c)  # every combination branches at its lowest item
    memo: dict[int, tuple[float, tuple[int, ...]]] = {0: (0.0, ())}

    def best(rest: int) -> tuple[float, tuple[int, ...]]:
        if rest in memo:
            return memo[rest]
        if len(memo) > max_states:
            raise _SearchTooLarge
        low = rest & -rest
        value, chosen = best(rest & ~low)  # the lowest item alone
        for c in by_low.get(low, ()):
            if masks[c] & rest == masks[c]:
                v, ch = best(rest & ~masks[c])
                if v + cost[c] < value - 1e-9:
                    value, chosen = v + cost[c], (c, *ch)
        memo[rest] = (value, chosen)
        return memo[rest]

    return [ids[c] for c in best(sum(bit.values()))[1]]


def _milp(members: list, cost: np.ndarray, items: np.ndarray, ids: list[int]) -> list[int]:
    """:func:`_search` as an integer program (scipy's ``milp``), for components too large to search."""
    from scipy.optimize import Bounds, LinearConstraint, milp
    from scipy.sparse import csr_array

    row_of = {int(b): k for k, b in enumerate(items)}
    sizes = [len(m) for m in members]
    rows = [row_of[int(b)] for m in members for b in m]
    cols = np.repeat(np.arange(len(members)), sizes)
    cover = csr_array((np.ones(len(rows)), (rows, cols)), shape=(len(items), len(members)))
    # Each item in at most one combination (alone otherwise, at cost 0).
    result = milp(cost, constraints=LinearConstraint(cover, 0, 1), integrality=np.ones(len(members)),
                  bounds=Bounds(0, 1))  # fmt: skip
    if result.x is None:  # cannot happen (choosing nothing is feasible), but never lose the frame
        return []
    return [ids[c] for c in np.flatnonzero(result.x > 0.5)]


def match_boxes(
    boxes: Sequence[np.ndarray],
    depths: Sequence[np.ndarray],
    cameras: Camera | Sequence[Camera],
    threshold_mm: float = 750.0,
    central_fraction: float = 0.5,
    grid: int = 7,
) -> list[Group]:
    """Group the boxes of V views into persons (see the module docstring).

    Args:
        boxes: V arrays ``(K_v, 4)`` xyxy pixels (K_v may be 0).
        depths: V depth images ``(H, W)`` uint16 mm (0 = unknown), of the same images as the boxes.
        cameras: V unbatched cameras, or one camera of batch shape (V,), of those images.
        threshold_mm: the largest distance allowed between any two centres of a combination (the paper's t).

    Returns:
        Groups, multi-view ones first (larger, then closer, first), then the unmatched boxes in view order.
    """
    centres, view = box_centres_3d(boxes, depths, cameras, central_fraction, grid)
    V, n = len(boxes), len(view)
    starts = np.concatenate([[0], np.cumsum([len(np.asarray(b).reshape(-1, 4)) for b in boxes])])
    local = np.arange(n) - starts[view]  # index of each box within its view

    chosen = choose_greedily(valid_combinations(centres, view, threshold_mm), n)
    if not chosen:
        return []
    # All group centres at once: the mean of the members' centres that have depth.
    member = np.zeros((len(chosen), n))  # (G, N) membership
    for g, (m, _) in enumerate(chosen):
        member[g, m] = 1.0
    has = ~np.isnan(centres[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = (member @ np.where(has[:, None], centres, 0.0)) / (member @ has)[:, None]  # (G, 3)
    indices = np.full((len(chosen), V), -1)
    rows = np.concatenate([np.full(len(m), g) for g, (m, _) in enumerate(chosen)])
    cols = np.concatenate([m for m, _ in chosen])
    indices[rows, view[cols]] = local[cols]
    return [Group(tuple(int(i) for i in indices[g]), centre[g], mean) for g, (_, mean) in enumerate(chosen)]
