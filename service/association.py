"""Which ground-truth person a detected person is, by box overlap: the paper's rule for detector mode.

The paper (Sec. "Bounding boxes from DETR") matches annotated boxes with the detected cross-view combinations
"based on the largest intersection over union (IoU), averaged over three camera views", scoring 0 for a view
where the combination has no box. Here that mean IoU over the V views is the score, and the assignment is the
one-to-one matching that maximises the total (Hungarian), keeping pairs whose mean IoU is above ``min_iou``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from posenet.data.sample import Sample


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every pair of xyxy boxes: ``a (N, 4)``, ``b (M, 4)`` -> ``(N, M)``."""
    lt = np.maximum(a[:, None, :2], b[None, :, :2])  # (N, M, 2)
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])  # (N, M, 2)
    inter = np.clip(rb - lt, 0, None).prod(-1)  # (N, M)
    area_a = (a[:, 2:] - a[:, :2]).prod(-1)
    area_b = (b[:, 2:] - b[:, :2]).prod(-1)
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def mean_view_iou(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Mean IoU over views between predicted and ground-truth persons.

    Args:
        pred: (P, V, 4) boxes of each predicted person per view, NaN where it has no box.
        gt: (G, V, 4) the same for the ground-truth persons.

    Returns:
        (P, G) the IoU averaged over the V views, a view where either has no box counting 0.
    """
    if pred.ndim != 3 or gt.ndim != 3 or pred.shape[1:] != gt.shape[1:] or pred.shape[2] != 4:
        raise ValueError(f"pred and gt must be (P, V, 4) and (G, V, 4), got {pred.shape} and {gt.shape}")
    P, V, _ = pred.shape
    G = gt.shape[0]
    if P == 0 or G == 0:
        return np.zeros((P, G))
    ious = box_iou(np.nan_to_num(pred.reshape(-1, 4)), np.nan_to_num(gt.reshape(-1, 4)))  # (P*V, G*V)
    ious = ious.reshape(P, V, G, V)[:, np.arange(V), :, np.arange(V)]  # (V, P, G): same view only
    present = ~np.isnan(pred[..., 0]).T[:, :, None] & ~np.isnan(gt[..., 0]).T[:, None, :]  # (V, P, G)
    return np.where(present, ious, 0.0).mean(axis=0)


def assign(
    pred_boxes: Sequence[Sequence[Sequence[float] | None]],
    gt_boxes: Sequence[Sequence[Sequence[float] | None]],
    min_iou: float = 0.1,
) -> list[int | None]:
    """For each predicted person, the index of its ground-truth person (or None).

    Args:
        pred_boxes: P persons, each V entries: an xyxy box or None.
        gt_boxes: G persons, each V entries: an xyxy box or None.
        min_iou: the least mean IoU for a pair to count as the same person.
    """

    def dense(persons) -> np.ndarray:
        rows = [[[np.nan] * 4 if b is None else list(b) for b in views] for views in persons]
        return np.asarray(rows, np.float64).reshape(len(persons), -1, 4)  # (N, V, 4)

    out: list[int | None] = [None] * len(pred_boxes)
    if not pred_boxes or not gt_boxes:
        return out
    score = mean_view_iou(dense(pred_boxes), dense(gt_boxes))  # (P, G)
    rows, cols = linear_sum_assignment(score, maximize=True)
    for r, c in zip(rows, cols, strict=True):
        if score[r, c] > min_iou:
            out[r] = int(c)
    return out


def ground_truth_ids(
    sample: Sample, pred_boxes: Sequence[Sequence[Sequence[float] | None]]
) -> list[int | None]:
    """The ground-truth person id of each predicted person of ``sample`` (None where none overlaps enough).

    Args:
        sample: the annotated frame; its boxes with a person id (>= 0) are the ground-truth persons.
        pred_boxes: P persons, each V entries: an xyxy box or None.
    """
    gt_ids = sorted({int(i) for view in sample.views for i in view.box_person_ids if i >= 0})
    matches = assign(pred_boxes, [sample.person_boxes(pid) for pid in gt_ids])
    return [None if g is None else gt_ids[g] for g in matches]
