"""``lifting.lift`` against the camera's own lifting (``Camera.unproject``): the same points, for views and for
persons x views of cameras, with and without distortion, and gradients that exist."""

from __future__ import annotations

import pytest
import torch

from posenet.cameras import Camera
from posenet.net.lifting import lift


def _cameras(batch: tuple[int, ...], distortion: bool) -> Camera:
    g = torch.Generator().manual_seed(0)
    n = int(torch.tensor(batch).prod())
    angles = torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1
    T = torch.eye(4, dtype=torch.float64).repeat(n, 1, 1)
    T[:, :3, :3] = torch.linalg.matrix_exp(
        torch.cross(torch.eye(3, dtype=torch.float64)[None], angles[:, None], dim=-1)
    )
    T[:, :3, 3] = torch.rand(n, 3, generator=g, dtype=torch.float64) * 4000 - 2000
    K = torch.tensor([270.0, 275.0, 159.5, 119.5], dtype=torch.float64).repeat(n, 1)
    d = (
        torch.tensor([0.1, -0.05, 0.001, -0.002, 0.01], dtype=torch.float64).repeat(n, 1)
        if distortion
        else None
    )
    return Camera(K.reshape(*batch, 4), T.reshape(*batch, 4, 4), None if d is None else d.reshape(*batch, 5))


@pytest.mark.parametrize("batch", [(3,), (2, 3)])
@pytest.mark.parametrize("distortion", [False, True])
def test_lift_equals_the_camera_s_unproject(batch, distortion):
    cams = _cameras(batch, distortion)
    g = torch.Generator().manual_seed(1)
    P = batch[0] if len(batch) == 2 else 1
    uv = torch.rand(P, batch[-1], 500, 2, generator=g) * torch.tensor([320.0, 240.0])
    depth = torch.rand(P, batch[-1], 500, generator=g) * 4000 + 500
    ours = lift(cams, uv, depth)
    reference = cams.to(dtype=torch.float32).unproject(uv, depth)[1]
    assert ours.shape == (P, batch[-1], 500, 3)
    torch.testing.assert_close(ours, reference, atol=2e-3, rtol=0)  # mm, float32 at metre scale


def test_lift_has_gradients():
    cams = _cameras((2,), False)
    uv = (torch.rand(1, 2, 50, 2, dtype=torch.float64) * 200).requires_grad_()
    depth = (torch.rand(1, 2, 50, dtype=torch.float64) * 3000 + 500).requires_grad_()
    lift(cams, uv, depth).sum().backward()
    assert torch.isfinite(uv.grad).all() and torch.isfinite(depth.grad).all() and uv.grad.abs().sum() > 0
