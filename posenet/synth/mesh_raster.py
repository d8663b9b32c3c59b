"""Vectorised triangle rasterisation of a :data:`~posenet.synth.primitives.MESH` primitive (NumPy).

The ray-cast primitives give a depth per pixel of their screen rectangle; a mesh gives the same, so
:func:`posenet.synth.raster.rasterize` keeps one z-buffer for both and occlusion between meshes, primitives and
the room is decided per pixel. For the pixels of the rectangle, :func:`rasterize_mesh` returns the nearest
triangle's depth and its interpolated vertex normal:

1. vertices are projected with the pinhole model (pixel centres at integer coordinates, as everywhere here);
   triangles facing away from the camera, or with a vertex nearer than ``NEAR_MM``, are dropped (people are
   closed surfaces seen from outside);
2. every triangle lists the pixel centres of its bounding box (one flat array over all triangles: ``np.repeat``
   of the box sizes, no Python loop), and keeps those inside its three edge functions (with a tolerance of
   1e-6 of its area, so that shared edges leave no cracks);
3. depth is interpolated as 1/z (exact for a planar triangle under perspective); the nearest candidate of each
   pixel wins (``np.minimum.at``), and its perspective-correct barycentrics interpolate the vertex normals.

The cost grows with the covered pixels plus the triangles, about 10-30 ms for a person of 15k triangles seen
at 3 m at 640x480 on one core.
"""

from __future__ import annotations

import numpy as np

NEAR_MM = 100.0


def rasterize_mesh(p, K, rect: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Depth ``(h, w)`` (np.inf where no triangle) and unit normals ``(3, h, w)`` of mesh primitive ``p`` (in the
    camera frame) over the pixel rectangle ``rect = (u0, u1, v0, v1)`` (half-open) of intrinsics ``K``."""
    u0, u1, v0, v1 = rect
    h, w = v1 - v0, u1 - u0
    depth = np.full(h * w, np.inf)
    normal = np.zeros((3, h * w), np.float32)
    m = p.mesh
    V = m.vertices.astype(np.float64, copy=False)
    f = m.faces
    z = V[:, 2]
    front = z > NEAR_MM
    zs = np.where(front, z, 1.0)
    u = K.fx * V[:, 0] / zs + K.cx
    v = K.fy * V[:, 1] / zs + K.cy
    ua, ub, uc = u[f[:, 0]], u[f[:, 1]], u[f[:, 2]]
    va, vb, vc = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    # Twice the signed screen area; with y down, a counter-clockwise (outward) triangle seen from outside has
    # a negative one.
    area = (ub - ua) * (vc - va) - (uc - ua) * (vb - va)
    keep = (area < 0) & front[f].all(1)
    lo_u = np.maximum(np.ceil(np.minimum(np.minimum(ua, ub), uc)), u0)
    hi_u = np.minimum(np.floor(np.maximum(np.maximum(ua, ub), uc)), u1 - 1)
    lo_v = np.maximum(np.ceil(np.minimum(np.minimum(va, vb), vc)), v0)
    hi_v = np.minimum(np.floor(np.maximum(np.maximum(va, vb), vc)), v1 - 1)
    nu = hi_u - lo_u + 1
    nv = hi_v - lo_v + 1
    keep &= (nu > 0) & (nv > 0)
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        return depth.reshape(h, w), normal.reshape(3, h, w)
    nu_k, nv_k = nu[idx].astype(np.int64), nv[idx].astype(np.int64)
    counts = nu_k * nv_k
    tri = np.repeat(idx, counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    local = np.arange(len(tri)) - start
    nu_t = np.repeat(nu_k, counts)
    pu = lo_u[tri] + local % nu_t
    pv = lo_v[tri] + local // nu_t
    # Barycentrics from the edge functions (each over the signed area).
    inv = 1.0 / area[tri]
    b0 = ((ub[tri] - pu) * (vc[tri] - pv) - (uc[tri] - pu) * (vb[tri] - pv)) * inv
    b1 = ((uc[tri] - pu) * (va[tri] - pv) - (ua[tri] - pu) * (vc[tri] - pv)) * inv
    b2 = 1.0 - b0 - b1
    eps = -1e-6
    inside = (b0 >= eps) & (b1 >= eps) & (b2 >= eps)
    tri, pu, pv, b0, b1, b2 = tri[inside], pu[inside], pv[inside], b0[inside], b1[inside], b2[inside]
    fz = 1.0 / zs[f[tri]]  # (N, 3) inverse depths of the corners
    inv_z = b0 * fz[:, 0] + b1 * fz[:, 1] + b2 * fz[:, 2]
    t = 1.0 / inv_z
    pix = (pv - v0).astype(np.int64) * w + (pu - u0).astype(np.int64)
    np.minimum.at(depth, pix, t)
    win = t <= depth[pix]
    tri, pix, t = tri[win], pix[win], t[win]
    # Perspective-correct barycentrics of the winners interpolate the vertex normals.
    c = np.stack([b0[win], b1[win], b2[win]], 1) * fz[win] * t[:, None]  # (N, 3)
    n = np.einsum("nk,nkd->nd", c.astype(np.float32), m.normals[f[tri]].astype(np.float32))
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
    normal[:, pix] = n.T
    return depth.reshape(h, w), normal.reshape(3, h, w)
