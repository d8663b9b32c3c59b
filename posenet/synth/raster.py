"""Ray casting of a list of primitives into a z-buffer, an id buffer and a normal buffer.

Each primitive is intersected only on the pixels of its screen rectangle (the projection of its bounding
spheres), vectorised over those pixels; the loop runs over primitives (a few dozen per frame), never over
pixels. Shading then needs normals only for the pixels that each primitive finally owns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posenet.synth.mesh_raster import rasterize_mesh
from posenet.synth.primitives import HIT, MESH, Primitive, normals

NEAR_MM = 100.0  # nothing closer than 10 cm to a camera is drawn


@dataclass
class Intrinsics:
    """A distortion-free pinhole camera of a ``width`` x ``height`` image (pixels, OpenCV convention)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 640
    height: int = 480


@dataclass
class GBuffer:
    """What a view sees.

    Attributes:
        depth: (H, W) float64 z in mm (np.inf where no surface).
        prim: (H, W) int32 index of the visible primitive (-1 for none).
        normal: (3, H, W) float32 unit normals in the camera frame (planar: one image per axis).
    """

    depth: np.ndarray
    prim: np.ndarray
    normal: np.ndarray


def screen_rect(p: Primitive, K: Intrinsics) -> tuple[int, int, int, int] | None:
    """Pixel rectangle ``(u0, u1, v0, v1)`` (half-open) that contains the primitive, or None if off-screen."""
    lo = np.array([np.inf, np.inf])
    hi = -lo
    seen = False
    for c, r in p.bounding_spheres():
        if c[2] + r < NEAR_MM:
            continue  # wholly behind the near plane
        seen = True
        if c[2] - r < NEAR_MM:  # straddles the camera: be conservative
            lo[:], hi[:] = -np.inf, np.inf
            break
        # x/z over the sphere lies between these extremes (both denominators cover either sign of x).
        xs = [
            (c[0] - r) / (c[2] - r),
            (c[0] - r) / (c[2] + r),
            (c[0] + r) / (c[2] - r),
            (c[0] + r) / (c[2] + r),
        ]
        ys = [
            (c[1] - r) / (c[2] - r),
            (c[1] - r) / (c[2] + r),
            (c[1] + r) / (c[2] - r),
            (c[1] + r) / (c[2] + r),
        ]
        lo = np.minimum(lo, [K.cx + K.fx * min(xs), K.cy + K.fy * min(ys)])
        hi = np.maximum(hi, [K.cx + K.fx * max(xs), K.cy + K.fy * max(ys)])
    if not seen:
        return None
    u0 = int(max(np.floor(lo[0]), 0))
    v0 = int(max(np.floor(lo[1]), 0))
    u1 = int(min(np.ceil(hi[0]) + 1, K.width))
    v1 = int(min(np.ceil(hi[1]) + 1, K.height))
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def rasterize(prims: list[Primitive], K: Intrinsics) -> GBuffer:
    """Render primitives already in the camera frame (see :meth:`Primitive.to_camera`)."""
    H, W = K.height, K.width
    du = (np.arange(W) - K.cx) / K.fx  # (W,)
    dv = (np.arange(H) - K.cy) / K.fy  # (H,)
    depth = np.full((H, W), np.inf)
    prim = np.full((H, W), -1, np.int32)
    mesh_normal = None  # (3, H, W) normals of the pixels that meshes own (they come with the depth)
    for i, p in enumerate(prims):
        rect = screen_rect(p, K)
        if rect is None:
            continue
        u0, u1, v0, v1 = rect
        if p.kind == MESH:
            t, n = rasterize_mesh(p, K, rect)
        else:
            t = HIT[p.kind](p, du[None, u0:u1], dv[v0:v1, None])  # (h, w)
        zb = depth[v0:v1, u0:u1]
        closer = (t < zb) & (t > NEAR_MM)
        zb[closer] = t[closer]
        prim[v0:v1, u0:u1][closer] = i
        if p.kind == MESH:
            if mesh_normal is None:
                mesh_normal = np.zeros((3, H, W), np.float32)
            mesh_normal[:, v0:v1, u0:u1][:, closer] = n[:, closer]

    normal = np.zeros((3, H * W), np.float32)
    flat = prim.ravel()
    order = np.argsort(flat, kind="stable")  # pixels grouped by the primitive that owns them
    sorted_ids = flat[order]
    starts = np.flatnonzero(np.diff(sorted_ids, prepend=sorted_ids[0] - 1))
    bounds = np.append(starts, len(flat))
    vv, uu = np.divmod(order, W)
    z = depth.ravel()[order].astype(np.float32)
    z[~np.isfinite(z)] = 0  # pixels that see nothing get no normal
    x, y = du.astype(np.float32)[uu] * z, dv.astype(np.float32)[vv] * z  # camera-frame surface points
    for k, start in enumerate(starts):  # one batch of pixels per visible primitive
        i = sorted_ids[start]
        if i < 0:
            continue
        sl = slice(start, bounds[k + 1])
        if prims[i].kind == MESH:
            normal[:, order[sl]] = mesh_normal.reshape(3, -1)[:, order[sl]]
            continue
        normal[:, order[sl]] = normals(prims[i], x[sl], y[sl], z[sl])
    return GBuffer(depth, prim, normal.reshape(3, H, W))
