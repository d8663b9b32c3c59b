"""Person boxes: their formats, their overlap, and the persons they belong to.

Every box in this project is ``xyxy`` in pixels of its image, in ``posenet.cameras``' pixel convention: the
origin is the *centre* of the top-left pixel, so an image of width W spans ``[-0.5, W - 0.5]``. The other
formats:

- **COCO** ``[x, y, w, h]`` (MVOR's annotations and COCO results files): ``x0 = x``, ``x1 = x + w``. MVOR's
  pixel numbers are already in the camera convention (its 2D keypoints agree with its own projections there),
  so there is no half-pixel shift: the same rule as ``posenet.data.mvor``.
- **DETR** ``(cx, cy, w, h)`` normalised by the image size, with the image spanning ``[0, 1]``: ``cx = (xc +
  0.5) / W``.

Resizing an image by a factor ``f`` maps a coordinate u to ``(u + 0.5) f - 0.5`` (as ``Camera.scale``), a
horizontal flip maps it to ``W - 1 - u``. The conversions take ``(..., 4)`` arrays or tensors and keep their
type (numpy in, numpy out; torch in, torch out), because they are pure arithmetic; the overlap measures and the
person rules are numpy (evaluation and matching, never in a gradient).

**Persons.** A box whose person id is ``>= 0`` belongs to that person; ``NO_IDENTITY`` (-1) marks a box without
an identity (MVOR annotates some boxes without a 3D pose or a name), which is never a person to estimate.
P persons across V views are one :class:`PersonBoxes`: ``(P, V, 4)`` boxes, a ``(P, V)`` mask of where a person
has a box, ``(P,)`` ids and, for detected boxes, ``(P, V)`` scores. It is the one dense form: the readers'
persons (``posenet.scene.Scene``), the pipeline's (``pipeline.two_stage.SceneResult.boxes``), the response's and
the evaluation's identity rule read it. Where a literal is handier (tests, the client's JSON), P lists of V
entries, each a box or None, convert with :meth:`PersonBoxes.from_lists`.

**The paper's identity rule** (Sec. "Bounding boxes from DETR"): a detected person is the annotated person whose
boxes it overlaps most, by IoU averaged over the V views (a view where either has no box scores 0), matched one
to one by the assignment that maximises the total (Hungarian).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

from posenet.cameras import rescale_pixels

NO_IDENTITY = -1  # the person id of a box that belongs to nobody known

ArrayLike = np.ndarray | torch.Tensor


def _check(name: str, boxes: ArrayLike) -> None:
    if boxes.ndim < 1 or boxes.shape[-1] != 4:
        raise ValueError(f"{name} must have shape (..., 4), got {tuple(boxes.shape)}")


def _stack(parts: list, like: ArrayLike) -> ArrayLike:
    if isinstance(like, torch.Tensor):
        return torch.stack(parts, dim=-1)
    return np.stack(parts, axis=-1)


def coco_to_xyxy(boxes: ArrayLike) -> ArrayLike:
    """COCO ``[x, y, w, h]`` ``(..., 4)`` to xyxy pixels."""
    _check("boxes", boxes)
    x, y, w, h = (boxes[..., i] for i in range(4))
    return _stack([x, y, x + w, y + h], boxes)


def xyxy_to_coco(boxes: ArrayLike) -> ArrayLike:
    """xyxy pixels ``(..., 4)`` to COCO ``[x, y, w, h]``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack([x0, y0, x1 - x0, y1 - y0], boxes)


def xyxy_to_cxcywh_norm(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """xyxy pixels ``(..., 4)`` to DETR's normalised ``(cx, cy, w, h)`` for an image of ``width x height``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack(
        [
            ((x0 + x1) / 2 + 0.5) / width,
            ((y0 + y1) / 2 + 0.5) / height,
            (x1 - x0) / width,
            (y1 - y0) / height,
        ],
        boxes,
    )


def cxcywh_norm_to_xyxy(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """DETR's normalised ``(cx, cy, w, h)`` ``(..., 4)`` to xyxy pixels of a ``width x height`` image."""
    _check("boxes", boxes)
    cx, cy, w, h = (boxes[..., i] for i in range(4))
    cx, cy, w, h = cx * width - 0.5, cy * height - 0.5, w * width, h * height
    return _stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], boxes)


def scale_xyxy(boxes: ArrayLike, factor: float) -> ArrayLike:
    """Boxes ``(..., 4)`` of an image resized by ``factor`` (0.5 halves it)."""
    _check("boxes", boxes)
    return rescale_pixels(boxes, factor)


def flip_xyxy(boxes: ArrayLike, width: int) -> ArrayLike:
    """Boxes ``(..., 4)`` of the horizontally flipped image of ``width`` pixels."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    return _stack([width - 1 - x1, y0, width - 1 - x0, y1], boxes)


def clip_xyxy(boxes: ArrayLike, width: int, height: int) -> ArrayLike:
    """Boxes ``(..., 4)`` clipped to the image ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``."""
    _check("boxes", boxes)
    x0, y0, x1, y1 = (boxes[..., i] for i in range(4))
    if isinstance(boxes, torch.Tensor):
        clamp = torch.clamp
    else:
        clamp = np.clip
    return _stack(
        [
            clamp(x0, -0.5, width - 0.5),
            clamp(y0, -0.5, height - 0.5),
            clamp(x1, -0.5, width - 0.5),
            clamp(y1, -0.5, height - 0.5),
        ],
        boxes,
    )


def area_xyxy(boxes: ArrayLike) -> ArrayLike:
    """Areas ``(...)`` of boxes ``(..., 4)``; inverted boxes have area 0."""
    _check("boxes", boxes)
    w = boxes[..., 2] - boxes[..., 0]
    h = boxes[..., 3] - boxes[..., 1]
    if isinstance(boxes, torch.Tensor):
        return w.clamp_min(0) * h.clamp_min(0)
    return np.maximum(w, 0) * np.maximum(h, 0)


def _intersection(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``a``, ``b`` as float64 xyxy boxes and the area of their intersection, broadcast (numpy)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    _check("a", a)
    _check("b", b)
    lo = np.maximum(a[..., :2], b[..., :2])
    hi = np.minimum(a[..., 2:], b[..., 2:])
    return a, b, np.prod(np.clip(hi - lo, 0, None), axis=-1)


def box_coverage(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The fraction of box ``b``'s area that box ``a`` covers, xyxy ``(..., 4)`` broadcast (numpy float64; 0 for
    a ``b`` of area 0)."""
    a, b, inter = _intersection(a, b)
    area = area_xyxy(b)
    return np.where(area > 0, inter / np.maximum(area, 1e-12), 0.0)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of xyxy boxes ``a (..., 4)`` and ``b (..., 4)``, broadcast against each other (numpy float64).

    Inverted boxes have area 0; two boxes of area 0 have IoU 0."""
    a, b, inter = _intersection(a, b)
    union = area_xyxy(a) + area_xyxy(b) - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def iou_xyxy(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairwise IoU ``(N, M)`` between boxes ``a (N, 4)`` and ``b (M, 4)`` (numpy, xyxy)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != 4 or b.shape[1] != 4:
        raise ValueError(f"iou_xyxy needs (N, 4) and (M, 4) boxes, got {a.shape} and {b.shape}")
    return box_iou(a[:, None, :], b[None, :, :])


def hull(boxes: np.ndarray) -> np.ndarray:
    """The smallest xyxy box ``(4,)`` holding every box of ``boxes`` ``(K, 4)``, K >= 1."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    return np.concatenate([boxes[:, :2].min(0), boxes[:, 2:].max(0)])


# ----------------------------------------------------------------------------------------------- persons
def identified(boxes: np.ndarray, person_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boxes ``(K', 4)`` of one view that belong to a person, and their ids ``(K',)`` (ids >= 0), in order.

    A person has one box per view: where a view repeats an id (the real MVOR file does, day 4 camera 3 frame
    38), its first box is kept, as :func:`boxes_of_person` reads it."""
    ids = np.asarray(person_ids).reshape(-1)
    _, first = np.unique(ids, return_index=True)
    keep = np.zeros(len(ids), bool)
    keep[first] = True
    keep &= ids >= 0
    return np.asarray(boxes)[keep], ids[keep]


def person_ids(ids_per_view: Sequence[np.ndarray]) -> list[int]:
    """The persons of a frame, sorted: every id >= 0 that has a box in some view (``ids_per_view``: V arrays)."""
    return sorted({int(i) for ids in ids_per_view for i in np.asarray(ids).reshape(-1) if i >= 0})


def boxes_of_person(
    boxes_per_view: Sequence[np.ndarray], ids_per_view: Sequence[np.ndarray], person_id: int
) -> list[np.ndarray | None]:
    """Per view, the (4,) box of ``person_id`` (its first, should a view hold two), or None where it has none."""
    out = []
    for boxes, ids in zip(boxes_per_view, ids_per_view, strict=True):
        hits = np.flatnonzero(np.asarray(ids) == person_id)
        out.append(boxes[hits[0]] if len(hits) else None)
    return out


@dataclass
class PersonBoxes:
    """P persons' boxes in V views: the one person-boxes type (module docstring).

    Attributes:
        boxes: (P, V, 4) float64 xyxy pixels of each person in each view; zeros where ``has_box`` is False.
        has_box: (P, V) bool, whether the person has a box in that view.
        ids: (P,) int64 person ids (the dataset's, the client's, or 0..P-1).
        scores: (P, V) float64 detector score of each box; NaN for a reference box and where there is none.
    """

    boxes: np.ndarray
    has_box: np.ndarray
    ids: np.ndarray
    scores: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.boxes = np.asarray(self.boxes, np.float64)
        self.has_box = np.asarray(self.has_box, bool)
        P = self.boxes.shape[0] if self.boxes.ndim == 3 else -1
        V = self.boxes.shape[1] if self.boxes.ndim == 3 else -1
        self.ids = np.arange(P, dtype=np.int64) if self.ids is None else np.asarray(self.ids, np.int64)
        if self.scores is None:
            self.scores = np.full((max(P, 0), max(V, 0)), np.nan)
        self.scores = np.asarray(self.scores, np.float64)
        if (
            self.boxes.shape != (P, V, 4)
            or self.has_box.shape != (P, V)
            or self.ids.shape != (P,)
            or self.scores.shape != (P, V)
        ):
            raise ValueError(
                "person boxes need boxes (P, V, 4), has_box (P, V), ids (P,) and scores (P, V), got "
                f"{self.boxes.shape}, {self.has_box.shape}, {self.ids.shape} and {self.scores.shape}"
            )

    @classmethod
    def from_lists(
        cls,
        person_boxes: Sequence[Sequence],
        num_views: int,
        ids: Sequence[int] | None = None,
        scores: Sequence[Sequence[float | None]] | None = None,
        check: bool = False,
    ) -> PersonBoxes:
        """P persons given as P lists of ``num_views`` entries, each an xyxy box or None (and, optionally, as
        many scores or None). ``ids`` default to 0..P-1.

        Refuses, naming the person, an entry count other than ``num_views``; with ``check`` also a box that is not
        finite with x1 > x0 and y1 > y0 (boxes from a client; :meth:`validate`).
        """
        P = len(person_boxes)
        boxes = np.zeros((P, num_views, 4))
        has = np.zeros((P, num_views), bool)
        for p, per_view in enumerate(person_boxes):
            if len(per_view) != num_views:
                raise ValueError(
                    f"person {p} has {len(per_view)} box entries, expected one per view ({num_views})"
                )
            for v, box in enumerate(per_view):
                if box is None:
                    continue
                b = np.asarray(box, np.float64).reshape(-1)
                if b.shape != (4,):
                    raise ValueError(f"person {p}, view {v}: a box is 4 numbers x0, y0, x1, y1, got {box}")
                boxes[p, v], has[p, v] = b, True
        dense_scores = None
        if scores is not None:
            dense_scores = np.array(
                [[np.nan if s is None else float(s) for s in per_view] for per_view in scores], np.float64
            ).reshape(P, num_views)
        out = cls(boxes, has, None if ids is None else list(ids), dense_scores)
        if check:
            out.validate()
        return out

    def validate(self) -> None:
        """Raise ValueError naming the first person and view whose box is not finite with x1 > x0, y1 > y0."""
        b = self.boxes
        bad = self.has_box & ~(np.isfinite(b).all(-1) & (b[..., 2] > b[..., 0]) & (b[..., 3] > b[..., 1]))
        if bad.any():
            p, v = np.argwhere(bad)[0]
            raise ValueError(
                f"person {p}, view {v}: box must be finite xyxy with x1 > x0, y1 > y0, got {b[p, v].tolist()}"
            )

    @classmethod
    def of(cls, persons: PersonBoxes | Sequence[Sequence], num_views: int | None = None) -> PersonBoxes:
        """``persons`` as they are, or converted from lists (:meth:`from_lists`; ``num_views`` then defaults to
        the first person's entries)."""
        if isinstance(persons, PersonBoxes):
            return persons
        if num_views is None:
            num_views = len(persons[0]) if len(persons) else 0
        return cls.from_lists(persons, num_views)

    def __len__(self) -> int:
        return self.boxes.shape[0]

    @property
    def num_views(self) -> int:
        return self.boxes.shape[1]

    def box(self, p: int, v: int) -> np.ndarray | None:
        """Person ``p``'s (4,) box in view ``v``, or None where it has none."""
        return self.boxes[p, v] if self.has_box[p, v] else None

    def score(self, p: int, v: int) -> float | None:
        """The detector score of person ``p``'s box in view ``v``, or None (no box, or a reference box)."""
        s = self.scores[p, v]
        return None if np.isnan(s) else float(s)

    def support(self, p: int) -> list[int]:
        """The views in which person ``p`` has a box."""
        return np.flatnonzero(self.has_box[p]).tolist()

    def select(self, rows) -> PersonBoxes:
        """The persons ``rows`` (indices or a (P,) bool mask), in that order."""
        return PersonBoxes(self.boxes[rows], self.has_box[rows], self.ids[rows], self.scores[rows])

    def rescaled(self, factors: Sequence[float]) -> PersonBoxes:
        """The boxes in images resized per view by ``factors`` (V,) (``posenet.cameras.rescale_pixels``); a
        view of factor 1 keeps its boxes bit for bit."""
        k = np.asarray(factors, np.float64).reshape(1, -1, 1)
        boxes = np.where(self.has_box[..., None] & (k != 1), rescale_pixels(self.boxes, k), self.boxes)
        return PersonBoxes(boxes, self.has_box, self.ids, self.scores)


# ----------------------------------------------------------------------------------------------- identity
def mean_view_iou(pred: PersonBoxes, gt: PersonBoxes) -> np.ndarray:
    """Mean IoU over views between predicted and ground-truth persons: ``(P, G)``, the IoU averaged over the V
    views, a view where either has no box counting 0."""
    if pred.num_views != gt.num_views:
        raise ValueError(
            f"pred and gt must be seen by the same views, got {pred.num_views} and {gt.num_views} views"
        )
    ious = box_iou(pred.boxes[:, None], gt.boxes[None])  # (P, G, V)
    present = pred.has_box[:, None, :] & gt.has_box[None]  # (P, G, V)
    return np.where(present, ious, 0.0).mean(axis=-1)


def match_persons(pred: PersonBoxes, gt: PersonBoxes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one-to-one matching of predicted to ground-truth persons that maximises the total mean-view IoU
    (:func:`mean_view_iou`).

    Returns:
        rows (M,) indices into ``pred``, cols (M,) into ``gt``, and their mean-view IoUs (M,);
        M = min(P, G).
    """
    score = mean_view_iou(pred, gt)  # (P, G)
    rows, cols = linear_sum_assignment(score, maximize=True)
    return rows, cols, score[rows, cols]


def assign(
    pred: PersonBoxes | Sequence[Sequence], gt: PersonBoxes | Sequence[Sequence], min_iou: float = 0.1
) -> list[int | None]:
    """For each predicted person, the index of its ground-truth person (or None).

    Args:
        pred: P persons (:class:`PersonBoxes`, or lists of V entries: an xyxy box or None).
        gt: G persons, the same.
        min_iou: the least mean IoU for a pair to count as the same person.
    """
    out: list[int | None] = [None] * len(pred)
    if not len(pred) or not len(gt):
        return out
    gt = PersonBoxes.of(gt)
    rows, cols, scores = match_persons(PersonBoxes.of(pred, gt.num_views), gt)
    for r, c, s in zip(rows, cols, scores, strict=True):
        if s > min_iou:
            out[r] = int(c)
    return out


def ground_truth_ids(sample, pred: PersonBoxes | Sequence[Sequence]) -> list[int | None]:
    """The ground-truth person id of each predicted person of ``sample`` (None where none overlaps enough).

    The paper's protocol: predicted persons are matched to the annotated ones by their IoU averaged over the
    views (0 where either has no box; :func:`assign`). The boxes MVOR annotates without an identity (``person_id``
    -1: people it boxed but gave no pose, such as the patient or someone barely in view) compete as well, each
    as a person of its one view, so a predicted person who overlaps one of them best is that person (None here)
    and is not scored against an annotated neighbour it barely overlaps (MOTChallenge's distractors; on the
    alt look's day 4, frame 44: one annotated person, seen by one camera, among four box-only ones).

    Args:
        sample: the annotated frame (a ``posenet.data.sample.Sample``); its persons are :func:`person_ids`.
        pred: the P predicted persons (:class:`PersonBoxes`, or lists of V entries: an xyxy box or None).
    """
    boxes = [np.asarray(v.boxes, np.float64).reshape(-1, 4) for v in sample.views]
    ids = [np.asarray(v.box_person_ids).reshape(-1) for v in sample.views]
    gt_ids = person_ids(ids)
    V = len(boxes)
    box_only = [[b if u == v else None for u in range(V)] for v in range(V) for b in boxes[v][ids[v] < 0]]
    matches = assign(PersonBoxes.of(pred, V), [boxes_of_person(boxes, ids, pid) for pid in gt_ids] + box_only)
    return [None if g is None or g >= len(gt_ids) else gt_ids[g] for g in matches]
