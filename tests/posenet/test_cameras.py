"""Cameras: OpenCV parity on MVOR's real cameras, round trips, gradients, batching, scale/crop, dtypes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from conftest import MVOR_CAMERAS_INFO

from posenet.cameras import Camera, is_rigid, pixel_grid, rigid_inverse, transform_points

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def mvor_cameras(use_distortion: bool) -> list[Camera]:
    return Camera.from_mvor(MVOR_CAMERAS_INFO, use_distortion=use_distortion)


def points_in_view(camera: Camera, n: int = 200, seed: int = 0, margin: float = 0.0) -> torch.Tensor:
    """(n, 3) reference-frame points, float64, that project inside the camera's image (depth 0.8 to 5 m)."""
    g = torch.Generator().manual_seed(seed)
    w, h = camera.size
    uv = torch.rand(n, 2, generator=g, dtype=torch.float64) * torch.tensor(
        [w - 1 - 2 * margin, h - 1 - 2 * margin]
    )
    uv = uv + margin
    depth = 800 + 4200 * torch.rand(n, generator=g, dtype=torch.float64)
    return camera.unproject(uv, depth)[1]


def cv2_project(camera: Camera, points_ref: torch.Tensor) -> np.ndarray:
    """OpenCV's projection of (N, 3) reference points with the camera's T(ref->v), K and distortion."""
    T = camera.ref_to_camera.numpy()
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    D = None if camera.distortion is None else camera.distortion.numpy()
    uv, _ = cv2.projectPoints(points_ref.numpy(), rvec, T[:3, 3], camera.K.numpy(), D)
    return uv[:, 0]


@pytest.mark.parametrize("use_distortion", [False, True])
@pytest.mark.parametrize("v", [0, 1, 2])
def test_project_matches_opencv_on_mvor_cameras(v: int, use_distortion: bool) -> None:
    camera = mvor_cameras(use_distortion)[v]
    # Points from the undistorted camera, so they cover the image whichever model projects them.
    points = points_in_view(mvor_cameras(False)[v], seed=v)
    ours = camera.project(points).numpy()
    np.testing.assert_allclose(ours, cv2_project(camera, points), atol=1e-6)


def test_mvor_distortion_is_reordered_to_opencv() -> None:
    # MVOR stores (k1, k2, k3, p1, p2); OpenCV wants (k1, k2, p1, p2, k3).
    k1, k2, k3, p1, p2 = MVOR_CAMERAS_INFO["camParams"]["intrinsics"][2]["distortion"]
    assert mvor_cameras(True)[2].distortion.tolist() == [k1, k2, p1, p2, k3]
    assert mvor_cameras(False)[2].distortion is None


@pytest.mark.parametrize("use_distortion", [False, True])
@pytest.mark.parametrize("v", [0, 1, 2])
def test_unproject_inverts_project_inside_the_image(v: int, use_distortion: bool) -> None:
    camera = mvor_cameras(use_distortion)[v]
    g = torch.Generator().manual_seed(10 + v)
    uv = torch.rand(500, 2, generator=g, dtype=torch.float64) * torch.tensor([639.0, 479.0])
    depth = 500 + 5000 * torch.rand(500, generator=g, dtype=torch.float64)
    points_cam, points_ref = camera.unproject(uv, depth)
    torch.testing.assert_close(points_cam[:, 2], depth)
    torch.testing.assert_close(camera.project(points_ref), uv, atol=1e-6, rtol=0)
    torch.testing.assert_close(camera.to_camera(points_ref), points_cam, atol=1e-6, rtol=0)


@pytest.mark.parametrize("v", [0, 1, 2])
def test_undistortion_matches_opencv(v: int) -> None:
    camera = mvor_cameras(True)[v]
    uv = pixel_grid(480, 640, dtype=torch.float64)[::37, ::41].reshape(-1, 2)  # (N, 2)
    if v == 0:
        # OpenCV's fixed-point iteration does not converge near this camera's corners; compare in the centre
        # (the round-trip test above covers the whole image).
        uv = uv[((uv - torch.tensor([320.0, 240.0])).abs() < torch.tensor([200.0, 150.0])).all(-1)]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    ref = cv2.undistortPoints(
        uv.numpy()[:, None], camera.K.numpy(), camera.distortion.numpy(), criteria=criteria
    )
    np.testing.assert_allclose(camera.normalised(uv).numpy(), ref[:, 0], atol=1e-7)


@pytest.mark.parametrize("v", [0, 1])
def test_gradcheck_unproject_and_transform(v: int) -> None:
    camera = mvor_cameras(True)[v]  # camera 0: the strongest distortion, where Newton's method matters
    g = torch.Generator().manual_seed(3)
    uv = (
        torch.rand(6, 2, generator=g, dtype=torch.float64) * torch.tensor([600.0, 440.0]) + 20
    ).requires_grad_()
    depth = (1000 + 3000 * torch.rand(6, generator=g, dtype=torch.float64)).requires_grad_()
    K = camera.intrinsics.clone().requires_grad_()
    T = camera.extrinsics.clone().requires_grad_()

    def lift(uv, depth, K, T):
        return Camera(K, T, camera.distortion).unproject(uv, depth)[1]

    assert torch.autograd.gradcheck(lift, (uv, depth, K, T))
    points = torch.randn(5, 3, generator=g, dtype=torch.float64).requires_grad_()
    assert torch.autograd.gradcheck(transform_points, (T, points))
    assert torch.autograd.gradcheck(rigid_inverse, (T,))
    assert torch.autograd.gradcheck(lambda p, K, T: Camera(K, T, camera.distortion).project(p),
                                    (points_in_view(camera, 5).requires_grad_(), K, T))  # fmt: skip


def test_rigid_inverse_and_is_rigid() -> None:
    T = torch.stack([c.extrinsics for c in mvor_cameras(False)])  # (3, 4, 4)
    assert is_rigid(T).all()
    torch.testing.assert_close(rigid_inverse(T), torch.linalg.inv(T))
    torch.testing.assert_close(rigid_inverse(T) @ T, torch.eye(4, dtype=T.dtype).expand(3, 4, 4))
    bad = T.clone()
    bad[0, 0, 0] = 2.0
    assert is_rigid(bad).tolist() == [False, True, True]


@pytest.mark.parametrize("use_distortion", [False, True])
def test_batched_cameras_equal_per_camera(use_distortion: bool) -> None:
    cams = mvor_cameras(use_distortion)
    stacked = Camera.stack(cams)
    points = torch.stack([points_in_view(mvor_cameras(False)[v], 50, seed=v) for v in range(3)])  # (V, N, 3)
    batched = stacked.project(points)  # (V, N, 2)
    for v, camera in enumerate(cams):
        torch.testing.assert_close(batched[v], camera.project(points[v]))
    # One point set against all cameras broadcasts: (N, 3) -> (V, N, 2).
    shared = stacked.project(points[0])
    for v, camera in enumerate(cams):
        torch.testing.assert_close(shared[v], camera.project(points[0]))
    depth = torch.full(batched.shape[:-1], 2000.0, dtype=torch.float64)
    lifted = stacked.unproject(batched, depth)[1]
    for v, camera in enumerate(cams):
        torch.testing.assert_close(lifted[v], camera.unproject(batched[v], depth[v])[1])


def test_stack_mixes_distorted_and_ideal_cameras() -> None:
    cams = [mvor_cameras(True)[0], mvor_cameras(False)[1]]
    stacked = Camera.stack(cams)
    assert stacked.distortion.shape == (2, 5) and (stacked.distortion[1] == 0).all()
    points = points_in_view(cams[1], 20)
    torch.testing.assert_close(stacked[1].project(points), cams[1].project(points))


@pytest.mark.parametrize("factor", [0.5, 0.25, 2.0])
@pytest.mark.parametrize("use_distortion", [False, True])
def test_scale_equals_scaling_the_pixels(factor: float, use_distortion: bool) -> None:
    camera = mvor_cameras(use_distortion)[2]
    points = points_in_view(mvor_cameras(False)[2], 100)
    expected = (camera.project(points) + 0.5) * factor - 0.5
    torch.testing.assert_close(camera.scale(factor).project(points), expected)
    assert camera.scale(factor).size == (round(640 * factor), round(480 * factor))


def test_scale_matches_cv2_resize_area_on_pixel_centres() -> None:
    # A bright pixel block at an even position becomes one pixel at the camera rule's position.
    image = np.zeros((480, 640), np.float32)
    image[200:202, 300:302] = 1.0  # centre (300.5, 200.5) in full-resolution pixels
    small = cv2.resize(image, (320, 240), interpolation=cv2.INTER_AREA)
    v, u = np.unravel_index(small.argmax(), small.shape)
    assert (u, v) == ((300.5 + 0.5) * 0.5 - 0.5, (200.5 + 0.5) * 0.5 - 0.5)


def test_crop_shifts_pixels() -> None:
    camera = mvor_cameras(True)[1]
    points = points_in_view(mvor_cameras(False)[1], 100)
    cropped = camera.crop(32.0, 16.0, 288, 208)
    expected = camera.project(points) - torch.tensor([32.0, 16.0], dtype=torch.float64)
    torch.testing.assert_close(cropped.project(points), expected)
    assert cropped.size == (288, 208)
    # Scale then crop: the paper's 320x240 image and its 288x208 training crop.
    both = camera.scale(0.5).crop(10, 20)
    shift = torch.tensor([10.0, 20.0], dtype=torch.float64)
    torch.testing.assert_close(both.project(points), (camera.project(points) + 0.5) * 0.5 - 0.5 - shift)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_any_dtype_and_device(dtype: torch.dtype, device: str) -> None:
    ref = mvor_cameras(True)[2]
    points64 = points_in_view(mvor_cameras(False)[2], 50)
    camera = ref.to(device=device, dtype=dtype)
    points = points64.to(device=device, dtype=dtype)
    uv = camera.project(points)
    assert uv.dtype == dtype and uv.device.type == device
    tol = 1e-2 if dtype == torch.float32 else 1e-8
    torch.testing.assert_close(uv.cpu().double(), ref.project(points64), atol=tol, rtol=0)
    lifted = camera.unproject(uv, camera.to_camera(points)[..., 2])[1]
    assert lifted.dtype == dtype
    torch.testing.assert_close(
        lifted.cpu().double(), points64, atol=0.5 if dtype == torch.float32 else 1e-6, rtol=0
    )
    assert pixel_grid(4, 6, device=device, dtype=dtype).shape == (4, 6, 2)


def test_points_behind_the_camera_stay_finite() -> None:
    camera = mvor_cameras(False)[0]
    uv = camera.project_camera(torch.tensor([[10.0, 5.0, 0.0], [10.0, 5.0, -100.0]], dtype=torch.float64))
    assert torch.isfinite(uv).all()


def test_pixel_grid_is_pixel_centres() -> None:
    grid = pixel_grid(3, 4)
    assert grid.shape == (3, 4, 2)
    assert grid[0, 0].tolist() == [0.0, 0.0] and grid[2, 3].tolist() == [3.0, 2.0]


def test_bad_shapes_raise() -> None:
    camera = mvor_cameras(False)[0]
    with pytest.raises(ValueError, match=r"points.*\(\.\.\., 3\)"):
        camera.project(torch.zeros(4, 2, dtype=torch.float64))
    with pytest.raises(ValueError, match="depth must have shape"):
        camera.unproject(torch.zeros(4, 2, dtype=torch.float64), torch.zeros(5, dtype=torch.float64))
    with pytest.raises(ValueError, match="intrinsics"):
        Camera(torch.zeros(3), torch.eye(4))
    with pytest.raises(ValueError, match="extrinsics"):
        Camera(torch.zeros(4), torch.eye(3))
    with pytest.raises(ValueError, match="empty"):
        Camera.stack([])
