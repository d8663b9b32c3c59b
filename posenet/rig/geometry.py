"""What a rig's geometry says about itself: camera spacing (units) and where the cameras look (directions).

Both are used twice: by the importers, to check the units and transform directions a file declares (or that its
format implies) and to report them, and by ``python -m posenet.rig check``. Every camera operation goes through
``posenet.cameras``.
"""

from __future__ import annotations

import itertools

import torch

from posenet.cameras import Camera, rigid_inverse

# Ceiling-mounted RGB-D cameras in a room are some decimetres to some tens of metres apart.
PLAUSIBLE_SPACING_MM = (150.0, 50_000.0)
UNITS_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


def camera_spacing(cameras: list[Camera]) -> float | None:
    """Median distance between the optical centres of all camera pairs (in the rig's unit); None for one camera."""
    if len(cameras) < 2:
        return None
    d = [float((a.position - b.position).norm()) for a, b in itertools.combinations(cameras, 2)]
    return float(torch.tensor(d).median())


def _length(mm: float) -> str:
    return f"{mm / 1000:.2f} m" if mm >= 1000 else f"{mm:.3g} mm"


def check_unit(cameras_mm: list[Camera], unit: str, source: str, declared: bool) -> str:
    """Check that translations read as ``unit`` give a plausible camera spacing; return the report line.

    ``cameras_mm`` are already converted to mm with ``unit``. Raises ValueError when the spacing is implausible
    but another unit would make it plausible, naming that unit (so nothing is silently rescaled).
    """
    spacing = camera_spacing(cameras_mm)
    how = "declared" if declared else "the format's unit"
    if spacing is None:
        return f"{source}: translations read as {unit} ({how}); one camera, so the unit cannot be checked"
    lo, hi = PLAUSIBLE_SPACING_MM
    line = f"{source}: translations read as {unit} ({how}): cameras a median {_length(spacing)} apart"
    if lo <= spacing <= hi:
        return line + " (plausible)"
    factor = UNITS_MM[unit]
    better = [u for u, f in UNITS_MM.items() if u != unit and lo <= spacing / factor * f <= hi]
    if better:
        raise ValueError(
            f"{line}, which is implausible for a room; read as {better[0]} they would be "
            f"{_length(spacing / factor * UNITS_MM[better[0]])} apart. Pass --unit {better[0]} if that is "
            "what the file holds."
        )
    return line + " (IMPLAUSIBLE for a room, and no other unit fixes it: check the file)"


def image_up(cameras: list[Camera]) -> torch.Tensor:
    """A first guess of the room's up (3,), unit, in the reference frame: the cameras' mean image-up axis (minus
    the camera y axis; cameras hang roughly upright, so their tilts largely cancel over a rig). Within some tens of
    degrees; ``posenet.rig.check.find_floor`` refines it on depth frames."""
    down = torch.stack([c.extrinsics[..., :3, 1] for c in cameras]).mean(0)
    return -down / down.norm()


def optical_axes(camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """``(*B, 3)`` optical centres and ``(*B, 3)`` unit viewing directions (the camera z axis) in the reference frame."""
    return camera.position, camera.extrinsics[..., :3, 2]


def look_at_point(camera: Camera) -> torch.Tensor:
    """(3,) the point nearest (least squares) to all optical axes of a stacked camera ``(V,)``."""
    c, d = optical_axes(camera)  # (V, 3) each
    eye = torch.eye(3, dtype=c.dtype)
    P = eye - d.unsqueeze(-1) * d.unsqueeze(-2)  # (V, 3, 3) projectors orthogonal to each axis
    A, b = P.sum(0), (P @ c.unsqueeze(-1)).sum(0)
    return torch.linalg.lstsq(A, b).solution.squeeze(-1)


def common_view(camera: Camera) -> dict:
    """Whether the V cameras of a stacked camera look at one common volume.

    Returns ``point`` (3,), the point nearest all optical axes; ``axis_distance_mm`` (V,), each axis's distance
    from it; ``depth_mm`` (V,), its depth in each camera; ``in_view`` (V,) bool, whether it is in front of the
    camera and, where the image size is known, inside its image.
    """
    V = camera.intrinsics.shape[0]
    if V < 2:
        raise ValueError(f"a common view needs at least two cameras, got {V}")
    point = look_at_point(camera)
    c, d = optical_axes(camera)
    offset = point - c  # (V, 3)
    along = (offset * d).sum(-1)
    distance = (offset - along.unsqueeze(-1) * d).norm(dim=-1)
    cam_points = camera.to_camera(point.expand(V, 1, 3))  # (V, 1, 3)
    uv = camera.project_camera(cam_points)[:, 0]  # (V, 2)
    in_view = cam_points[:, 0, 2] > 0
    if camera.size is not None:
        w, h = camera.size
        in_view &= (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
    return {"point": point, "axis_distance_mm": distance, "depth_mm": cam_points[:, 0, 2], "in_view": in_view}


def check_direction(cameras: list[Camera], source: str, meaning: str) -> str:
    """Report whether the extrinsics, read as ``meaning`` (T(v->ref)), make the cameras share a view.

    When they do not but the inverted transforms would, the line says so loudly: the file's direction is probably
    the other one. Nothing is changed here.
    """
    if len(cameras) < 2:
        return f"{source}: extrinsics read as {meaning}; one camera, so the direction cannot be checked"
    stack = Camera.stack(cameras)
    inverted = Camera(stack.intrinsics, rigid_inverse(stack.extrinsics), stack.distortion, stack.size)
    ok, flipped = common_view(stack), common_view(inverted)
    n, m, V = int(ok["in_view"].sum()), int(flipped["in_view"].sum()), len(cameras)
    spread, spread_flipped = float(ok["axis_distance_mm"].mean()), float(flipped["axis_distance_mm"].mean())
    line = (
        f"{source}: extrinsics read as {meaning}: the point nearest all optical axes is in view of {n}/{V} "
        f"cameras, the axes pass it at a mean {spread:.0f} mm (read the other way round: {m}/{V}, "
        f"{spread_flipped:.0f} mm)"
    )
    if m > n or (m == n and spread_flipped < 0.5 * spread):
        return line + "; WARNING: the other direction fits better, the file may hold the inverse transforms"
    return line + (" (consistent)" if n == V else "")
