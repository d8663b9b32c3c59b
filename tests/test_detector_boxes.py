"""Box conversions: round trips, agreement with the camera's resize rule, IoU against a brute-force
reference."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from detector import boxes as B
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
