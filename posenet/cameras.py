"""Pinhole RGB-D cameras and the frames they live in.

The convention, fixed here once and used by every other module:

- **Units.** Millimetres for every 3D coordinate, pixels for 2D.
- **Camera frame.** OpenCV's: x right, y down, z forward. Depth is the z coordinate (not the ray length).
- **Pixels.** (u, v) with the origin at the *centre* of the top-left pixel, u to the right, v down.
- **Intrinsics.** fx, fy, cx, cy, plus optional distortion (k1, k2, p1, p2, k3) in OpenCV's order.
- **Extrinsics.** ``extrinsics`` is the 4x4 rigid transform T(v->ref) that maps a point in this camera's frame
  to the reference frame (camera 0's frame): ``p_ref = R @ p_cam + t``. This is MVOR's
  ``cameras_info.camParams.extrinsics[v]`` and the paper's T^{v->0}.
- **Resizing** an image by a factor s maps pixel u to ``(u + 0.5) * s - 0.5``, so pixel centres stay pixel
  centres (what ``cv2.resize`` with ``INTER_AREA`` does for integer subsampling). **Cropping** at (x0, y0)
  maps u to ``u - x0``.

Batching: a :class:`Camera` holds tensors with a batch shape ``B``: ``intrinsics (*B, 4)``, ``distortion (*B, 5)``
or ``None``, ``extrinsics (*B, 4, 4)``. Point arguments are ``(*P, N, 3)`` (pixels ``(*P, N, 2)``, depths
``(*P, N)``) where ``P`` broadcasts against ``B``. So one camera serves any batch of points, and a stack of V
cameras serves ``(V, N, 3)`` points, one row of points per camera. Everything is plain torch: differentiable,
and it works on any device and floating dtype.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

Tensor = torch.Tensor

# Newton iterations used to invert the distortion model. OpenCV's fixed-point iteration (undistortPoints) does
# not converge near the corners of MVOR's first camera (k3 = 6.5: errors up to 68 px); Newton's method on the
# (monotonic inside the image) distortion map reaches 1e-12 in a handful of steps.
_UNDISTORT_ITERS = 12


def _check_last(name: str, x: Tensor, size: int) -> None:
    if x.ndim < 1 or x.shape[-1] != size:
        raise ValueError(f"{name} must have shape (..., {size}), got {tuple(x.shape)}")


def is_rigid(T: Tensor, atol: float = 1e-4) -> Tensor:
    """Whether each 4x4 matrix ``T (..., 4, 4)`` is a proper rigid transform (rotation + translation)."""
    R = T[..., :3, :3]
    eye = torch.eye(3, dtype=T.dtype, device=T.device)
    bottom = torch.tensor([0, 0, 0, 1], dtype=T.dtype, device=T.device)
    ortho = (R @ R.transpose(-1, -2) - eye).abs().amax(dim=(-1, -2)) < atol
    # det R as the triple product: torch.linalg.det goes through LAPACK, whose calls on a request's path cost far
    # more than these few multiplications when the inference runtime's threads hold the cores
    det = ((R[..., 0, :] * torch.linalg.cross(R[..., 1, :], R[..., 2, :], dim=-1)).sum(-1) - 1).abs() < atol
    last = (T[..., 3, :] - bottom).abs().amax(dim=-1) < atol
    return ortho & det & last & torch.isfinite(T).all(dim=-1).all(dim=-1)


def rigid_inverse(T: Tensor) -> Tensor:
    """Inverse of rigid transforms ``T (..., 4, 4)``, computed as ``[R^T, -R^T t]`` (exact and differentiable)."""
    R = T[..., :3, :3]
    t = T[..., :3, 3:]
    Rt = R.transpose(-1, -2)
    top = torch.cat([Rt, -Rt @ t], dim=-1)  # (..., 3, 4)
    bottom = torch.zeros_like(T[..., 3:, :])
    bottom[..., 3] = 1
    return torch.cat([top, bottom], dim=-2)


def transform_points(T: Tensor, points: Tensor) -> Tensor:
    """Apply 4x4 transforms ``T (*B, 4, 4)`` to ``points (*P, N, 3)``; B and P broadcast."""
    _check_last("points", points, 3)
    R = T[..., :3, :3].unsqueeze(-3)  # (*B, 1, 3, 3)
    t = T[..., :3, 3].unsqueeze(-2)  # (*B, 1, 3)
    return (R @ points.unsqueeze(-1)).squeeze(-1) + t


def rescale_pixels(u, factor):
    """Pixel coordinates ``u`` (any float array, tensor or number) in an image resized by ``factor``:
    ``(u + 0.5) * factor - 0.5``, so that pixel centres stay pixel centres (the convention above). The one place
    this rule is written: cameras, boxes and crops all rescale through it."""
    return (u + 0.5) * factor - 0.5


@dataclass(frozen=True)
class Camera:
    """A pinhole camera (see the module docstring for every convention).

    Attributes:
        intrinsics: (*B, 4) fx, fy, cx, cy in pixels.
        extrinsics: (*B, 4, 4) T(v->ref), mm.
        distortion: (*B, 5) k1, k2, p1, p2, k3 (OpenCV order), or None for an ideal pinhole.
        size: (width, height) of the image this camera describes, in pixels, or None if unknown.
    """

    intrinsics: Tensor
    extrinsics: Tensor
    distortion: Tensor | None = None
    size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        _check_last("intrinsics", self.intrinsics, 4)
        if self.extrinsics.shape[-2:] != (4, 4):
            raise ValueError(f"extrinsics must have shape (..., 4, 4), got {tuple(self.extrinsics.shape)}")
        if self.distortion is not None:
            _check_last("distortion", self.distortion, 5)

    # ----------------------------------------------------------------- construction
    @classmethod
    def create(
        cls,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        extrinsics: Sequence[float] | Tensor | None = None,
        distortion: Sequence[float] | Tensor | None = None,
        size: tuple[int, int] | None = None,
        dtype: torch.dtype = torch.float64,
    ) -> Camera:
        """One camera from plain numbers. ``extrinsics`` is T(v->ref) as 16 numbers (row-major) or 4x4."""
        K = torch.tensor([fx, fy, cx, cy], dtype=dtype)
        T = torch.eye(4, dtype=dtype) if extrinsics is None else torch.as_tensor(extrinsics, dtype=dtype)
        T = T.reshape(4, 4)
        D = None if distortion is None else torch.as_tensor(distortion, dtype=dtype).reshape(5)
        return cls(K, T, D, size)

    @classmethod
    def from_mvor(cls, cameras_info: dict, use_distortion: bool = False) -> list[Camera]:
        """The cameras of an MVOR-format ``cameras_info`` block, in the order of ``camParams.intrinsics``.

        MVOR stores distortion as (k1, k2, k3, p1, p2); it is reordered here to OpenCV's (k1, k2, p1, p2, k3).
        MVOR's own tools, and its 3D annotations, ignore distortion, hence ``use_distortion=False`` by default.
        """
        params = cameras_info["camParams"]
        cams = []
        for intr, ext in zip(params["intrinsics"], params["extrinsics"], strict=True):
            (fx, fy), (cx, cy) = intr["focallength"], intr["principalpoint"]
            dist = None
            if use_distortion and intr.get("distortion") is not None:
                k1, k2, k3, p1, p2 = intr["distortion"]
                dist = [k1, k2, p1, p2, k3]
            size = tuple(intr["imagesize"]) if intr.get("imagesize") else None
            cams.append(cls.create(fx, fy, cx, cy, ext, dist, size))
        return cams

    @staticmethod
    def stack(cameras: Sequence[Camera]) -> Camera:
        """Stack unbatched cameras into one camera of batch shape (V,)."""
        if not cameras:
            raise ValueError("cannot stack an empty list of cameras")
        dists = [c.distortion for c in cameras]
        if any(d is None for d in dists) and not all(d is None for d in dists):
            dists = [
                torch.zeros_like(c.intrinsics[..., :1].expand(5)) if d is None else d
                for c, d in zip(cameras, dists, strict=True)
            ]
        D = None if all(d is None for d in dists) else torch.stack(dists)
        sizes = {c.size for c in cameras}
        return Camera(
            torch.stack([c.intrinsics for c in cameras]),
            torch.stack([c.extrinsics for c in cameras]),
            D,
            sizes.pop() if len(sizes) == 1 else None,
        )

    def __getitem__(self, index) -> Camera:
        D = None if self.distortion is None else self.distortion[index]
        return Camera(self.intrinsics[index], self.extrinsics[index], D, self.size)

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None) -> Camera:
        D = None if self.distortion is None else self.distortion.to(device=device, dtype=dtype)
        return Camera(
            self.intrinsics.to(device=device, dtype=dtype),
            self.extrinsics.to(device=device, dtype=dtype),
            D,
            self.size,
        )

    # ----------------------------------------------------------------- properties
    @property
    def fx(self) -> Tensor:
        return self.intrinsics[..., 0]

    @property
    def fy(self) -> Tensor:
        return self.intrinsics[..., 1]

    @property
    def cx(self) -> Tensor:
        return self.intrinsics[..., 2]

    @property
    def cy(self) -> Tensor:
        return self.intrinsics[..., 3]

    @property
    def K(self) -> Tensor:
        """(*B, 3, 3) intrinsic matrix."""
        z, o = torch.zeros_like(self.fx), torch.ones_like(self.fx)
        rows = [
            torch.stack([self.fx, z, self.cx], -1),
            torch.stack([z, self.fy, self.cy], -1),
            torch.stack([z, z, o], -1),
        ]
        return torch.stack(rows, -2)

    @property
    def ref_to_camera(self) -> Tensor:
        """(*B, 4, 4) T(ref->v), the inverse of ``extrinsics``."""
        return rigid_inverse(self.extrinsics)

    @property
    def position(self) -> Tensor:
        """(*B, 3) the optical centre in the reference frame, mm."""
        return self.extrinsics[..., :3, 3]

    # ----------------------------------------------------------------- frames
    def to_ref(self, points_cam: Tensor) -> Tensor:
        """Camera-frame points ``(*P, N, 3)`` to reference-frame points."""
        return transform_points(self.extrinsics, points_cam)

    def to_camera(self, points_ref: Tensor) -> Tensor:
        """Reference-frame points ``(*P, N, 3)`` to camera-frame points."""
        return transform_points(self.ref_to_camera, points_ref)

    # ----------------------------------------------------------------- projection
    def _k(self, i: int) -> Tensor:
        return self.intrinsics[..., i].unsqueeze(-1)  # (*B, 1): broadcasts over N

    def _distort(self, x: Tensor, y: Tensor) -> tuple[Tensor, Tensor]:
        """Apply the distortion model to normalised coordinates ``(*P, N)``."""
        d = self.distortion.unsqueeze(-2)  # (*B, 1, 5)
        k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return xd, yd

    def project_camera(self, points_cam: Tensor, eps: float = 1e-6) -> Tensor:
        """Camera-frame points ``(*P, N, 3)`` to pixels ``(*P, N, 2)`` (distortion applied if present).

        Points at or behind the camera (z <= eps) are clamped to z = eps instead of producing infinities.
        """
        _check_last("points_cam", points_cam, 3)
        z = points_cam[..., 2].clamp_min(eps)
        x, y = points_cam[..., 0] / z, points_cam[..., 1] / z
        if self.distortion is not None:
            x, y = self._distort(x, y)
        return torch.stack([self._k(0) * x + self._k(2), self._k(1) * y + self._k(3)], dim=-1)

    def project(self, points_ref: Tensor) -> Tensor:
        """Reference-frame points ``(*P, N, 3)`` to pixels ``(*P, N, 2)``."""
        return self.project_camera(self.to_camera(points_ref))

    def normalised(self, uv: Tensor) -> Tensor:
        """Pixels ``(*P, N, 2)`` to undistorted normalised coordinates ``(*P, N, 2)`` (x/z, y/z)."""
        _check_last("uv", uv, 2)
        xd = (uv[..., 0] - self._k(2)) / self._k(0)
        yd = (uv[..., 1] - self._k(3)) / self._k(1)
        if self.distortion is None:
            return torch.stack([xd, yd], dim=-1)
        # Solve distort(x, y) = (xd, yd) by Newton's method without autograd, then take one more Newton step
        # with autograd: at the solution that step's gradient is the implicit-function gradient J^-1.
        with torch.no_grad():
            x, y = xd.detach(), yd.detach()
            for _ in range(_UNDISTORT_ITERS):
                x, y = self._newton_step(x, y, xd.detach(), yd.detach(), self.distortion.detach())
        x, y = self._newton_step(x, y, xd, yd, self.distortion)
        return torch.stack([x, y], dim=-1)

    @staticmethod
    def _newton_step(
        x: Tensor, y: Tensor, xd: Tensor, yd: Tensor, distortion: Tensor
    ) -> tuple[Tensor, Tensor]:
        """One Newton step towards distort(x, y) = (xd, yd), normalised coordinates ``(*P, N)``."""
        d = distortion.unsqueeze(-2)  # (*B, 1, 5)
        k1, k2, p1, p2, k3 = (d[..., i] for i in range(5))
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
        fx = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xd
        fy = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - yd
        # Jacobian of the distortion map [[a, b], [c, e]], inverted in closed form.
        a = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
        b = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y
        e = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
        det = a * e - b * b  # the Jacobian is symmetric: c == b
        return x - (e * fx - b * fy) / det, y - (a * fy - b * fx) / det

    def unproject(self, uv: Tensor, depth: Tensor) -> tuple[Tensor, Tensor]:
        """Lift pixels ``(*P, N, 2)`` with depths ``(*P, N)`` (mm along z) to 3D.

        Returns ``(points_cam, points_ref)``, each ``(*P, N, 3)`` in mm. This is the paper's lifting,
        ``(D (u - cx) / fx, D (v - cy) / fy, D)``, followed by T(v->ref).
        """
        if depth.shape != uv.shape[:-1]:
            raise ValueError(
                f"depth must have shape {tuple(uv.shape[:-1])} to match uv, got {tuple(depth.shape)}"
            )
        xy = self.normalised(uv)
        points_cam = torch.cat([xy * depth.unsqueeze(-1), depth.unsqueeze(-1)], dim=-1)
        return points_cam, self.to_ref(points_cam)

    # ----------------------------------------------------------------- image operations
    def scale(self, factor: float) -> Camera:
        """The camera of the image resized by ``factor`` (0.5 halves it): pixel u maps to (u + 0.5) f - 0.5."""
        f = float(factor)
        K = self.intrinsics.clone()
        K[..., :2] = K[..., :2] * f
        K[..., 2:] = rescale_pixels(K[..., 2:], f)
        size = None if self.size is None else (round(self.size[0] * f), round(self.size[1] * f))
        return Camera(K, self.extrinsics, self.distortion, size)

    def crop(self, x0: float, y0: float, width: int | None = None, height: int | None = None) -> Camera:
        """The camera of the image cropped with its top-left pixel at (x0, y0): pixel u maps to u - x0."""
        K = self.intrinsics.clone()
        K[..., 2] = K[..., 2] - x0
        K[..., 3] = K[..., 3] - y0
        size = (width, height) if width is not None and height is not None else None
        return Camera(K, self.extrinsics, self.distortion, size)


def pixel_grid(height: int, width: int, device=None, dtype=torch.float32) -> Tensor:
    """``(H, W, 2)`` pixel coordinates (u, v) of every pixel centre, in this module's convention."""
    v, u = torch.meshgrid(
        torch.arange(height, device=device, dtype=dtype),
        torch.arange(width, device=device, dtype=dtype),
        indexing="ij",
    )
    return torch.stack([u, v], dim=-1)
