"""Ray-primitive intersections and normals of the synthetic renderer, against their implicit surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from posenet.synth.primitives import (
    BOX,
    CAPSULE,
    CONE,
    ELLIPSOID,
    HIT,
    box,
    capsule,
    ellipsoid,
    normals,
    round_cone,
    shell,
)
from posenet.synth.raster import Intrinsics, rasterize, screen_rect


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _shapes(rng: np.random.Generator):
    centre = np.array([rng.uniform(-300, 300), rng.uniform(-300, 300), rng.uniform(2000, 3000)])
    R = _rotation(rng)
    return [
        ellipsoid(centre, rng.uniform(80, 300, 3), R),
        capsule(centre - R[:, 0] * 250, centre + R[:, 0] * 250, rng.uniform(40, 120)),
        box(centre, rng.uniform(80, 300, 3), R),
        round_cone(centre - R[:, 1] * 220, centre + R[:, 1] * 220, rng.uniform(90, 140), rng.uniform(30, 80)),
    ]


def _sdf(p, pts: np.ndarray) -> np.ndarray:
    """Signed distance-like implicit value (0 on the surface) of points ``(N, 3)``."""
    if p.kind == ELLIPSOID:
        local = (pts - p.center) @ p.rotation / p.size
        return np.linalg.norm(local, axis=1) - 1
    if p.kind == CAPSULE:
        ba = p.b - p.a
        s = np.clip((pts - p.a) @ ba / (ba @ ba), 0, 1)
        return np.linalg.norm(pts - (p.a + s[:, None] * ba), axis=1) - p.size[0]
    if p.kind == CONE:  # Inigo Quilez's exact sdRoundCone
        r1, r2 = p.size[0], p.size[1]
        ba = p.b - p.a
        l2 = ba @ ba
        rr = r1 - r2
        a2 = l2 - rr * rr
        pa = pts - p.a
        y = pa @ ba
        z = y - l2
        x2 = (((pa * l2) - np.outer(y, ba)) ** 2).sum(1)
        y2, z2 = y * y * l2, z * z * l2
        k = np.sign(rr) * rr * rr * x2
        side = (np.sqrt(x2 * a2 / l2) + y * rr) / l2 - r1
        out = np.where(np.sign(y) * a2 * y2 < k, np.sqrt(x2 + y2) / l2 - r1, side)
        return np.where(np.sign(z) * a2 * z2 > k, np.sqrt(x2 + z2) / l2 - r2, out)
    local = (pts - p.center) @ p.rotation / p.size
    return np.abs(local).max(axis=1) - 1


@pytest.mark.parametrize("seed", range(4))
def test_hits_lie_on_the_surface_and_are_the_first_crossing(seed):
    rng = np.random.default_rng(seed)
    for p in _shapes(rng):
        dx = rng.uniform(-0.25, 0.25, (1, 400))
        dy = rng.uniform(-0.25, 0.25, (1, 400))
        t = HIT[p.kind](p, dx, dy)[0]
        hit = np.isfinite(t)
        assert hit.any() and (~hit).any(), "rays should both hit and miss"
        dirs = np.stack([dx[0], dy[0], np.ones(400)], 1)
        on = dirs[hit] * t[hit, None]
        in_mm = p.kind in (CAPSULE, CONE)  # these implicit values are distances in mm, the others relative
        assert np.abs(_sdf(p, on)).max() < (0.5 if in_mm else 2e-3)
        # The point slightly before the hit is outside: the hit is the first crossing.
        before = dirs[hit] * (t[hit, None] - 2.0)
        assert (_sdf(p, before) > 0).all()
        # Missed rays never enter the shape (brute-force march).
        ts = np.linspace(1000, 4500, 700)
        march = dirs[~hit][:, None, :] * ts[None, :, None]
        assert (_sdf(p, march.reshape(-1, 3)) > -1e-6).all()


@pytest.mark.parametrize("seed", range(3))
def test_normals_match_the_implicit_gradient(seed):
    rng = np.random.default_rng(seed)
    for p in _shapes(rng):
        dx = rng.uniform(-0.2, 0.2, (1, 300))
        dy = rng.uniform(-0.2, 0.2, (1, 300))
        t = HIT[p.kind](p, dx, dy)[0]
        hit = np.isfinite(t)
        pts = np.stack([dx[0], dy[0], np.ones(300)], 1)[hit] * t[hit, None]
        n = normals(p, *pts.T).T
        assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-4)
        eps = 0.05
        grad = np.stack([(_sdf(p, pts + e) - _sdf(p, pts - e)) / (2 * eps) for e in np.eye(3) * eps], 1)
        grad /= np.linalg.norm(grad, axis=1, keepdims=True)
        agree = (n * grad).sum(1)
        if p.kind == BOX:  # edges are ambiguous: most points sit on a face
            assert np.mean(agree > 0.999) > 0.95
        else:
            assert agree.min() > 0.999
        # Normals face the camera (at the origin) on the visible side.
        assert ((n * pts).sum(1) < 1e-3).all()


def test_screen_rect_contains_every_hit_pixel():
    rng = np.random.default_rng(0)
    K = Intrinsics(540.0, 540.0, 320.0, 240.0, 640, 480)
    for p in _shapes(rng):
        g = rasterize([p], K)
        u0, u1, v0, v1 = screen_rect(p, K)
        rows, cols = np.nonzero(g.prim == 0)
        assert len(rows) > 50
        assert rows.min() >= v0 and rows.max() < v1 and cols.min() >= u0 and cols.max() < u1


def test_zbuffer_keeps_the_nearest_surface_and_shell_fills_the_rest():
    K = Intrinsics(540.0, 540.0, 320.0, 240.0, 640, 480)
    room = shell([0, 0, 2000], [3000, 3000, 4000])
    far = box([0, 0, 3000], [400, 400, 50])
    near = ellipsoid([0, 0, 2000], [200, 200, 200])
    g = rasterize([room, far, near], K)
    assert (g.prim >= 0).all(), "the shell closes the room: every pixel sees a surface"
    assert g.prim[240, 320] == 2 and abs(g.depth[240, 320] - 1800) < 1
    assert g.prim[240, 320 + 70] == 1 and abs(g.depth[240, 320 + 70] - 2950) < 1
    dx, dy = (5 - 320) / 540, (5 - 240) / 540
    assert g.prim[5, 5] == 0 and g.depth[5, 5] == pytest.approx(
        min(6000, 3000 / abs(dx), 3000 / abs(dy)), abs=1
    )
    # Rendering order does not matter.
    g2 = rasterize([near, room, far], K)
    assert np.array_equal(g.depth, g2.depth)


def test_box_geometry_matches_the_project_camera_model():
    import torch

    from posenet.boxes import box_iou
    from posenet.synth.boxes import covered, project_boxes
    from posenet.synth.rig import random_rig

    rng = np.random.default_rng(1)
    rig = random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 3)
    pts = rng.uniform([-400, -400, 200], [400, 400, 1700], (2, 12, 3))  # (C, N, 3) world points
    boxes = project_boxes(rig, pts)  # (V, C, 4)
    for v, cam in enumerate(rig.cameras):  # posenet.rig.Rig: Cameras whose reference frame is the world
        uv = cam.project(torch.as_tensor(pts)).numpy()
        expect = np.concatenate([uv.min(1), uv.max(1)], 1).clip(0, [639, 479, 639, 479])
        assert np.allclose(boxes[v], expect, atol=1e-6)
    a, b = np.array([0.0, 0, 10, 10]), np.array([5.0, 0, 15, 10])
    assert box_iou(a, a) == pytest.approx(1) and box_iou(a, b) == pytest.approx(
        box_iou(b, a)
    ) == pytest.approx(1 / 3)
    assert covered(a, b) == pytest.approx(0.5) and covered(np.array([20.0, 20, 30, 30]), a) == 0
