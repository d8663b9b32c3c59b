import numpy as np
import pytest
import torch

from posenet.cameras import Camera
from posenet.net.lifting import EPS_LOGIT, aggregate, centre_of_mass_2d, fuse_2d, lift, masked_logits


def _cameras(V: int, dtype=torch.float64) -> Camera:
    cams = []
    for v in range(V):
        T = np.eye(4)
        a = 0.3 * v
        T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
        T[:3, 3] = [400.0 * v, -50.0 * v, 100.0 * v]
        cams.append(Camera.create(30.0 + v, 31.0, 7.5, 5.5, T, dtype=dtype))
    return Camera.stack(cams)


def _scene(P=2, V=3, J=4, M=12, seed=0, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    logits = torch.randn(P, V, J, M, generator=g, dtype=dtype)
    uv = torch.rand(P, V, M, 2, generator=g, dtype=dtype) * 15
    depth = 2000 + 500 * torch.rand(P, V, M, generator=g, dtype=dtype)
    valid = torch.rand(P, V, M, generator=g) > 0.3
    valid[:, 0, 0] = True
    return logits, uv, depth, valid


def test_gradcheck_lift_and_aggregate():
    logits, uv, depth, valid = _scene(P=2, V=2, J=2, M=5)
    cams = _cameras(2)
    logits.requires_grad_(True)
    depth.requires_grad_(True)
    uv.requires_grad_(True)

    def f(lg, d, u):
        est = aggregate(lg, lift(cams, u, d), valid)
        return est.joints, est.spread_mm

    assert torch.autograd.gradcheck(f, (logits, depth, uv))


def test_parity_with_numpy_loop():
    logits, uv, depth, valid = _scene(P=2, V=3, J=4, M=9, seed=1)
    cams = _cameras(3)
    points = lift(cams, uv, depth)
    est = aggregate(logits, points, valid)
    L, X, ok = logits.numpy(), points.numpy(), valid.numpy()
    for p in range(2):
        for j in range(4):
            z = np.concatenate([L[p, v, j][ok[p, v]] for v in range(3)])
            x = np.concatenate([X[p, v][ok[p, v]] for v in range(3)])
            w = np.exp(z - z.max())
            w /= w.sum()
            ref = w @ x
            np.testing.assert_allclose(est.joints[p, j].numpy(), ref, rtol=1e-9, atol=1e-7)
            spread = np.sqrt((w * ((x - ref) ** 2).sum(1)).sum())
            np.testing.assert_allclose(est.spread_mm[p, j].numpy(), spread, rtol=1e-5)


def test_lift_matches_pinhole_formula_and_extrinsics():
    cams = _cameras(2)
    uv = torch.tensor([[[[3.0, 4.0]], [[10.0, 1.0]]]], dtype=torch.float64)  # (1, 2, 1, 2)
    d = torch.tensor([[[2000.0], [1500.0]]], dtype=torch.float64)
    pts = lift(cams, uv, d)
    for v in range(2):
        fx, fy, cx, cy = cams.intrinsics[v].tolist()
        (u, vv), z = uv[0, v, 0].tolist(), d[0, v, 0].item()
        p_cam = torch.tensor([z * (u - cx) / fx, z * (vv - cy) / fy, z, 1.0], dtype=torch.float64)
        torch.testing.assert_close(pts[0, v, 0], (cams.extrinsics[v] @ p_cam)[:3])


def test_invalid_points_have_no_influence_and_finite_gradients():
    logits, uv, depth, valid = _scene(seed=2)
    cams = _cameras(3)
    a = aggregate(logits, lift(cams, uv, depth), valid)
    depth2 = torch.where(valid, depth, torch.zeros_like(depth))  # unknown depth on masked points
    lg = logits.clone().requires_grad_(True)
    b = aggregate(lg, lift(cams, uv, depth2), valid)
    torch.testing.assert_close(a.joints, b.joints)
    b.joints.sum().backward()
    assert torch.isfinite(lg.grad).all()
    assert (lg.grad.permute(0, 2, 1, 3)[~valid.unsqueeze(1).expand(-1, 4, -1, -1)] == 0).all()


def test_single_view_and_peaked_heatmap():
    cams = _cameras(1)
    logits, uv, depth, valid = _scene(P=1, V=1, J=2, M=6, seed=3)
    valid[:] = True
    logits[0, 0, :, 4] = 200.0  # all mass on point 4
    est = aggregate(logits, lift(cams, uv, depth), valid)
    target = lift(cams, uv, depth)[0, 0, 4]
    torch.testing.assert_close(est.joints[0], target.expand(2, 3))
    assert (est.spread_mm < 1e-2).all()
    fused = fuse_2d(logits, uv, depth, valid, cams)
    torch.testing.assert_close(fused.joints[0], target.expand(2, 3))


def test_confidence_is_spread_in_mm():
    # two equally weighted points 200 mm apart: estimate in the middle, spread 100 mm
    points = torch.tensor([[[[0.0, 0, 1000], [200.0, 0, 1000]]]], dtype=torch.float64)  # (1, 1, 2, 3)
    est = aggregate(
        torch.zeros(1, 1, 1, 2, dtype=torch.float64), points, torch.ones(1, 1, 2, dtype=torch.bool)
    )
    torch.testing.assert_close(est.joints[0, 0], torch.tensor([100.0, 0, 1000], dtype=torch.float64))
    assert abs(est.spread_mm.item() - 100.0) < 1e-3


def test_all_masked_person_is_flagged():
    logits, uv, depth, valid = _scene(P=2, V=2, J=2, M=4, seed=4)
    valid[1] = False
    est = aggregate(logits, lift(_cameras(2), uv, depth), valid, EPS_LOGIT)
    assert est.has_points.tolist() == [True, False]
    assert torch.isfinite(est.joints).all()


def test_fuse_2d_views_weighted_by_logit():
    cams = _cameras(2)
    logits, uv, depth, valid = _scene(P=1, V=2, J=1, M=5, seed=5)
    valid[:] = True
    logits[:] = -50.0
    logits[0, 0, 0, 1] = 50.0  # view 0: sharp and confident
    logits[0, 1, 0, 3] = 10.0  # view 1: sharp, much lower logit
    est = fuse_2d(logits, uv, depth, valid, cams)
    torch.testing.assert_close(est.joints[0, 0], lift(cams, uv, depth)[0, 0, 1])
    uv_hat, vv = centre_of_mass_2d(logits, uv, valid)
    torch.testing.assert_close(uv_hat[0, 1, 0], uv[0, 1, 3])
    assert vv.all()


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="logits"):
        aggregate(torch.zeros(2, 3, 4), torch.zeros(1, 1, 4, 3), torch.ones(1, 1, 4, dtype=torch.bool))
    with pytest.raises(ValueError, match="views"):
        lift(
            _cameras(2),
            torch.zeros(1, 3, 4, 2, dtype=torch.float64),
            torch.zeros(1, 3, 4, dtype=torch.float64),
        )


def test_masked_logits_equals_where_with_its_gradient():
    g = torch.Generator().manual_seed(3)
    logits = (torch.randn(3, 2, 10, 50, generator=g) * 20).requires_grad_()
    valid = torch.rand(3, 2, 50, generator=g) > 0.4
    out = masked_logits(logits, valid)
    ref = torch.where(valid.unsqueeze(2), logits, torch.full_like(logits, EPS_LOGIT))
    assert torch.equal(out, ref)  # bit-identical, not just close
    (grad,) = torch.autograd.grad((out * torch.arange(50.0)).sum(), logits)
    assert torch.equal(grad, valid.unsqueeze(2).expand_as(logits) * torch.arange(50.0))
