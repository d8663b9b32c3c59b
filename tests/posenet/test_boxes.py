"""``posenet.boxes``: conversions (round trips, agreement with the camera's resize rule), IoU and the mean
IoU over views against brute-force references, and the rule of which boxes are persons."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from posenet import boxes as B
from posenet.cameras import Camera


@pytest.fixture
def xyxy():
    rng = np.random.default_rng(0)
    lo = rng.uniform(-0.5, 300, (50, 2))
    return np.concatenate([lo, lo + rng.uniform(1, 100, (50, 2))], axis=1)


def test_coco_round_trip(xyxy):
    np.testing.assert_allclose(B.coco_to_xyxy(B.xyxy_to_coco(xyxy)), xyxy, atol=1e-9)
    coco = B.xyxy_to_coco(xyxy)
    np.testing.assert_allclose(B.xyxy_to_coco(B.coco_to_xyxy(coco)), coco, atol=1e-9)


def test_coco_matches_the_mvor_reader():
    """The MVOR reader's rule: (x, y, w, h) -> (x, y, x + w, y + h), no half-pixel shift."""
    np.testing.assert_allclose(B.coco_to_xyxy(np.array([287.0, 207, 134.5, 273])), [287, 207, 421.5, 480])


def test_detr_round_trip_numpy_and_torch(xyxy):
    norm = B.xyxy_to_cxcywh_norm(xyxy, 320, 240)
    np.testing.assert_allclose(B.cxcywh_norm_to_xyxy(norm, 320, 240), xyxy, atol=1e-9)
    t = torch.from_numpy(xyxy)
    tn = B.xyxy_to_cxcywh_norm(t, 320, 240)
    assert isinstance(tn, torch.Tensor)
    np.testing.assert_allclose(tn.numpy(), norm, atol=1e-12)
    # The whole image is the unit square.
    np.testing.assert_allclose(
        B.xyxy_to_cxcywh_norm(np.array([-0.5, -0.5, 319.5, 239.5]), 320, 240), [0.5] * 2 + [1] * 2
    )


def test_scale_matches_camera_and_inverts(xyxy):
    cam = Camera.create(500.0, 500.0, 319.5, 239.5)
    half = cam.scale(0.5)
    # A box corner maps like a pixel: through the camera's own resize rule.
    ray = torch.tensor([[0.1, -0.2, 1.0]], dtype=torch.float64)
    u_full, u_half = cam.project_camera(ray)[0], half.project_camera(ray)[0]
    box = np.array([u_full[0], u_full[1], u_full[0] + 10, u_full[1] + 10])
    np.testing.assert_allclose(B.scale_xyxy(box, 0.5)[:2], u_half.numpy(), atol=1e-9)
    np.testing.assert_allclose(B.scale_xyxy(B.scale_xyxy(xyxy, 0.5), 2.0), xyxy, atol=1e-9)


def test_flip_is_an_involution(xyxy):
    np.testing.assert_allclose(B.flip_xyxy(B.flip_xyxy(xyxy, 640), 640), xyxy)
    f = B.flip_xyxy(xyxy, 640)
    assert (f[:, 2] >= f[:, 0]).all()
    np.testing.assert_allclose(B.area_xyxy(f), B.area_xyxy(xyxy))


def test_iou_against_brute_force(xyxy):
    a, b = xyxy[:7], xyxy[7:12]
    iou = B.iou_xyxy(a, b)
    for i in range(len(a)):
        for j in range(len(b)):
            ix = max(0, min(a[i, 2], b[j, 2]) - max(a[i, 0], b[j, 0]))
            iy = max(0, min(a[i, 3], b[j, 3]) - max(a[i, 1], b[j, 1]))
            inter = ix * iy
            union = (
                (a[i, 2] - a[i, 0]) * (a[i, 3] - a[i, 1]) + (b[j, 2] - b[j, 0]) * (b[j, 3] - b[j, 1]) - inter
            )
            assert iou[i, j] == pytest.approx(inter / union)
    np.testing.assert_allclose(np.diag(B.iou_xyxy(a, a)), 1.0)


def test_clip_and_bad_shapes():
    clipped = B.clip_xyxy(np.array([[-10.0, -10, 700, 500]]), 640, 480)
    np.testing.assert_allclose(clipped, [[-0.5, -0.5, 639.5, 479.5]])
    with pytest.raises(ValueError, match=r"\(\.\.\., 4\)"):
        B.coco_to_xyxy(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="iou_xyxy"):
        B.iou_xyxy(np.zeros((2, 4)), np.zeros(4))


def test_broadcast_iou_equals_the_pairwise_one(xyxy):
    a, b = xyxy[:7], xyxy[7:12]
    np.testing.assert_array_equal(B.box_iou(a[:, None], b[None]), B.iou_xyxy(a, b))
    np.testing.assert_allclose(B.box_iou(a, a), 1.0)
    line = np.array([3.0, 3, 3, 9])  # area 0 (a projected box clipped to the image border)
    assert B.box_iou(line, line) == 0.0 and B.box_iou(line, a[0]) == 0.0


def test_mean_view_iou_against_brute_force(xyxy):
    rng = np.random.default_rng(1)
    P, G, V = 4, 3, 3
    pred, gt = xyxy[: P * V].reshape(P, V, 4).copy(), xyxy[20 : 20 + G * V].reshape(G, V, 4).copy()
    gt[:2] = pred[:2] + rng.normal(0, 5, (2, V, 4))  # two persons overlap their detection
    pred_has, gt_has = np.ones((P, V), bool), np.ones((G, V), bool)
    pred_has[0, 1] = False  # missed in one view
    gt_has[2, 0] = False  # not in view 0
    pred_p, gt_p = B.PersonBoxes(pred, pred_has, None), B.PersonBoxes(gt, gt_has, None)
    got = B.mean_view_iou(pred_p, gt_p)
    for p in range(P):
        for g in range(G):
            ious = [
                B.iou_xyxy(pred[p, v][None], gt[g, v][None])[0, 0] if pred_has[p, v] and gt_has[g, v] else 0.0
                for v in range(V)
            ]
            assert got[p, g] == pytest.approx(np.mean(ious))
    rows, cols, scores = B.match_persons(pred_p, gt_p)
    assert len(rows) == G and set(rows[cols < 2]) == {0, 1} and list(cols[rows < 2]) == [0, 1]
    np.testing.assert_allclose(scores, got[rows, cols])


def test_persons_are_the_boxes_with_an_identity():
    boxes = [np.arange(12.0).reshape(3, 4), np.arange(8.0).reshape(2, 4) + 100, np.zeros((0, 4))]
    ids = [np.array([-1, 3, 1]), np.array([1, -1]), np.zeros(0, np.int64)]
    assert B.person_ids(ids) == [1, 3]
    kept, kept_ids = B.identified(boxes[0], ids[0])
    np.testing.assert_array_equal(kept, boxes[0][1:])
    assert kept_ids.tolist() == [3, 1]
    # a view that repeats an id (the real MVOR file has one) keeps that person's first box, as boxes_of_person
    twice, twice_ids = B.identified(boxes[0], np.array([1, -1, 1]))
    np.testing.assert_array_equal(twice, boxes[0][:1])
    assert twice_ids.tolist() == [1]
    np.testing.assert_array_equal(B.boxes_of_person([boxes[0]], [np.array([1, -1, 1])], 1)[0], twice[0])
    one = B.boxes_of_person(boxes, ids, 1)
    np.testing.assert_array_equal(one[0], boxes[0][2])
    np.testing.assert_array_equal(one[1], boxes[1][0])
    assert one[2] is None and B.boxes_of_person(boxes, ids, 7) == [None, None, None]
    dense = B.PersonBoxes.from_lists([one], 3, ids=[1])
    assert dense.boxes.shape == (1, 3, 4) and dense.has_box.tolist() == [[True, True, False]]
    assert dense.box(0, 2) is None and (dense.box(0, 1) == one[1]).all() and dense.support(0) == [0, 1]
    assert dense.ids.tolist() == [1] and dense.score(0, 0) is None and not dense.boxes[0, 2].any()


def test_predicted_persons_take_the_identity_they_overlap_best_box_only_people_included():
    from types import SimpleNamespace

    # View 0: person 4 (annotated) beside someone MVOR boxed without an identity (-1); view 1: person 4 alone.
    a, other = [100.0, 50, 160, 240], [130.0, 40, 210, 240]
    view0 = SimpleNamespace(boxes=np.array([a, other]), box_person_ids=np.array([4, -1]))
    view1 = SimpleNamespace(boxes=np.array([[10.0, 10, 60, 200]]), box_person_ids=np.array([4]))
    sample = SimpleNamespace(views=[view0, view1])
    on_other = [[128.0, 45, 208, 238], None]  # the box-only person, seen in view 0: overlaps person 4 too
    as_boxes = B.PersonBoxes.from_lists
    assert B.mean_view_iou(as_boxes([on_other], 2), as_boxes([[a, view1.boxes[0]]], 2))[0, 0] > 0.1
    on_a = [[102.0, 52, 158, 238], [12.0, 11, 61, 199]]
    far = [[0.0, 0, 5, 5], None]
    assert B.ground_truth_ids(sample, [on_other, on_a, far]) == [None, 4, None]
    assert B.ground_truth_ids(sample, as_boxes([on_other, on_a, far], 2)) == [None, 4, None]  # the dense form
    # Alone it still goes to the box-only person; were that box not in the file, the mean IoU of 0.1 and more
    # would score it against person 4 (what offering only the identified boxes did before 2026-12-05).
    assert B.ground_truth_ids(sample, [on_other]) == [None]
    alone = SimpleNamespace(views=[SimpleNamespace(boxes=np.array([a]), box_person_ids=np.array([4])), view1])
    assert B.ground_truth_ids(alone, [on_other]) == [4]


def test_box_coverage_is_the_covered_fraction_of_the_second_box():
    from posenet.boxes import box_coverage

    big, small = np.array([0.0, 0, 10, 10]), np.array([2.0, 2, 4, 4])
    assert box_coverage(big, small) == 1.0 and box_coverage(small, big) == pytest.approx(0.04)
    half = np.array([5.0, 0, 15, 10])
    assert box_coverage(half, big) == pytest.approx(0.5)
    assert box_coverage(np.stack([big, half]), big).tolist() == pytest.approx([1.0, 0.5])  # broadcast
    assert box_coverage(big, np.array([3.0, 3, 3, 3])) == 0.0  # nothing to cover


def test_person_boxes_round_trip_select_rescale_and_refuse_bad_boxes(xyxy):
    lists = [[xyxy[0], None, xyxy[1]], [None, xyxy[2], None]]
    boxes = B.PersonBoxes.from_lists(lists, 3, ids=[7, 3], scores=[[0.9, None, 0.4], [None, None, None]])
    for p, per_view in enumerate(lists):  # the dense form gives back every entry, and None where there is none
        assert [None if b is None else b.tolist() for b in per_view] == [
            None if boxes.box(p, v) is None else boxes.box(p, v).tolist() for v in range(3)
        ]
    assert boxes.support(0) == [0, 2] and boxes.score(0, 2) == 0.4 and boxes.score(1, 1) is None
    second = boxes.select([1])
    assert len(second) == 1 and second.ids.tolist() == [3] and second.support(0) == [1]
    # rescaling is the camera rule per view, a view of factor 1 untouched bit for bit, the mask and scores kept
    half = boxes.rescaled([0.5, 1, 2])
    np.testing.assert_array_equal(half.boxes[0, 0], (xyxy[0] + 0.5) * 0.5 - 0.5)
    np.testing.assert_array_equal(half.boxes[1, 1], xyxy[2])
    np.testing.assert_array_equal(half.boxes[0, 2], B.scale_xyxy(xyxy[1], 2.0))
    assert (half.has_box == boxes.has_box).all() and not half.boxes[0, 1].any()
    np.testing.assert_array_equal(half.scores, boxes.scores)
    with pytest.raises(ValueError, match=r"person 1, view 0: box must be finite xyxy"):
        B.PersonBoxes.from_lists([[None], [[5.0, 5, 4, 9]]], 1, check=True)
    with pytest.raises(ValueError, match=r"person 0 has 2 box entries, expected one per view \(3\)"):
        B.PersonBoxes.from_lists([[None, None]], 3)
    with pytest.raises(ValueError, match=r"has_box \(P, V\)"):
        B.PersonBoxes(np.zeros((2, 3, 4)), np.zeros((2, 2), bool), None)
