"""The check picture: the cameras' frusta seen from above, over the floor, shaded by how many views see each spot.

The floor's normal ("up") is the room frame's z axis when the rig has one (MVOR's ``firstCamToRoomRef``), else
the given ``up`` vector, else the opposite of the cameras' mean image-down axis (ceiling cameras are mounted
roughly upright). Coverage is counted on the *working plane*: the horizontal plane through the point nearest all
optical axes, where the cameras were aimed (an OR's table height). A spot counts for a camera when it projects
inside that camera's image in front of it and within ``max_range_mm``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from posenet.rig.geometry import image_up, look_at_point
from posenet.rig.rigfile import Rig


def up_vector(rig: Rig, up: torch.Tensor | None = None) -> tuple[Rig, torch.Tensor, str]:
    """The rig in the frame to draw in, its unit up vector (3,) and where that came from."""
    if up is not None:
        return rig, up / up.norm(), "given"
    if rig.to_room is not None:
        return rig.to_room_frame(), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64), "room frame z"
    return rig, image_up(rig.cameras), "cameras' mean image-up axis"


def coverage(rig: Rig, points: torch.Tensor, max_range_mm: float) -> torch.Tensor:
    """(V, N) bool: whether each camera sees each reference-frame point ``(N, 3)``."""
    cam = rig.stacked
    V = len(rig)
    in_cam = cam.to_camera(points.expand(V, *points.shape))  # (V, N, 3)
    uv = cam.project_camera(in_cam)
    z = in_cam[..., 2]
    seen = (z > 0) & (in_cam.norm(dim=-1) < max_range_mm)
    sizes = [c.size for c in rig.cameras]
    if all(s is not None for s in sizes):
        wh = torch.tensor(sizes, dtype=points.dtype).unsqueeze(1)  # (V, 1, 2)
        seen &= ((uv >= -0.5) & (uv <= wh - 0.5)).all(-1)
    return seen


def draw_rig(rig: Rig, path: str | Path, up: torch.Tensor | None = None, max_range_mm: float = 8000.0,
             title: str | None = None, resolution_mm: float = 50.0, floor_mm: float | None = None,
             up_source: str | None = None) -> dict:  # fmt: skip
    """Write the picture to ``path`` (PNG); returns what it drew (``up``, ``plane_height_mm``, ``coverage``).

    ``floor_mm``: the floor's height along ``up`` when known (``check.find_floor`` on depth frames), drawn in the
    side view.
    """
    import matplotlib

    matplotlib.use("Agg")  # files only; imported here so that importing this module changes nothing
    import matplotlib.pyplot as plt

    rig, up, source = up_vector(rig, up)
    up_source = up_source or source
    up = up.to(torch.float64)
    e1 = torch.linalg.cross(up, torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64))
    if e1.norm() < 1e-3:
        e1 = torch.linalg.cross(up, torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64))
    e1 = e1 / e1.norm()
    e2 = torch.linalg.cross(up, e1)
    centres = torch.stack([c.position for c in rig.cameras])  # (V, 3)
    target = (
        look_at_point(rig.stacked) if len(rig) > 1 else centres[0] + 3000 * rig.cameras[0].extrinsics[:3, 2]
    )
    height = float(target @ up)

    ends_all = []
    for c in rig.cameras:
        w, h = c.size if c.size is not None else (2 * float(c.cx) + 1, 2 * float(c.cy) + 1)
        corners = torch.tensor(
            [[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]], dtype=torch.float64
        )
        rays = (
            torch.cat([c.normalised(corners), torch.ones(4, 1, dtype=torch.float64)], -1)
            @ c.extrinsics[:3, :3].T
        )
        # Corner rays end on the working plane, or at max range when they miss it.
        t = (height - float(c.position @ up)) / (rays @ up)
        t = torch.where((t > 0) & (t * rays.norm(dim=-1) < max_range_mm), t, max_range_mm / rays.norm(dim=-1))
        ends_all.append(c.position + t.unsqueeze(-1) * rays)  # (4, 3)

    # Coverage on the working plane, over the cameras' surroundings.
    everything = torch.cat([centres, *ends_all])
    xy = torch.stack([everything @ e1, everything @ e2], -1)
    txy = torch.stack([target @ e1, target @ e2])
    lo, hi = xy.min(0).values - 500, xy.max(0).values + 500
    xs = torch.arange(float(lo[0]), float(hi[0]), resolution_mm, dtype=torch.float64)
    ys = torch.arange(float(lo[1]), float(hi[1]), resolution_mm, dtype=torch.float64)
    gx, gy = torch.meshgrid(xs, ys, indexing="xy")  # (H, W)
    plane = gx.reshape(-1, 1) * e1 + gy.reshape(-1, 1) * e2 + height * up  # (N, 3)
    count = coverage(rig, plane, max_range_mm).sum(0).reshape(gx.shape)  # (H, W)

    fig, (top, side) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [1.4, 1]})
    V = len(rig)
    cmap = plt.get_cmap("viridis", V + 1)
    im = top.imshow(count.numpy(), origin="lower", cmap=cmap, vmin=-0.5, vmax=V + 0.5,
                    extent=[float(xs[0]) / 1000, float(xs[-1]) / 1000, float(ys[0]) / 1000, float(ys[-1]) / 1000])  # fmt: skip
    fig.colorbar(im, ax=top, ticks=range(V + 1), label="cameras that see the working plane", shrink=0.8)
    colours = plt.get_cmap("tab10")
    for v, (c, ends) in enumerate(zip(rig.cameras, ends_all, strict=True)):
        col = colours(v % 10)
        for pts, ax in (
            (torch.stack([ends @ e1, ends @ e2], -1), top),
            (torch.stack([ends @ e1, ends @ up], -1), side),
        ):
            o = (torch.stack([c.position @ e1, c.position @ (e2 if ax is top else up)])).numpy() / 1000
            p = pts.numpy() / 1000
            for q in p:
                ax.plot([o[0], q[0]], [o[1], q[1]], color=col, lw=1)
            ax.plot(*np.vstack([p, p[:1]]).T, color=col, lw=1.5)
            ax.plot(*o, "o", color=col, ms=7, mec="k")
            ax.annotate(f"{v}: {rig.names[v]}", o, textcoords="offset points", xytext=(6, 6), color=col, fontsize=9,
                        fontweight="bold")  # fmt: skip
    for ax in (top, side):
        ax.plot(float(txy[0]) / 1000, float(txy[1] if ax is top else height) / 1000, "r+", ms=14, mew=2)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    top.set(xlabel="m", ylabel="m", title=f"from above: frusta cut at the working plane ({up_source})")
    side.axhline(height / 1000, color="r", lw=0.8, ls="--")
    label = "from the side (red: working plane"
    if floor_mm is not None:
        side.axhline(floor_mm / 1000, color="k", lw=2)
        label += ", black: floor"
    side.set(xlabel="m", ylabel="height along up, m", title=label + ")")
    fig.suptitle(title or f"{V} cameras, frame: {rig.frame}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    seen = count > 0
    return {"up": up, "up_source": up_source, "plane_height_mm": height,
            "coverage": {k: float((count >= k).sum()) * resolution_mm**2 / 1e6 for k in range(1, V + 1)},
            "seen": bool(seen.any())}  # fmt: skip
