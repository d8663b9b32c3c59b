"""The room's static depth, per camera, learned over a stream: what never moves is background.

A stream's tracker (``pipeline.track.Tracker``) confirms a new track only when the stream has seen its person move,
stand where the static background is not, or hold a pose no static object explains. This module answers the second
question. Per camera it keeps a coarse background depth image (every ``step``-th pixel, ``grid_width`` columns
whatever the image size) that follows the frames' depth images:

- **Farther wins fast.** Where a frame's depth lies farther than the background, what stood in front has gone:
  the background moves ``reveal_rate`` of the way there per frame (a person walking away uncovers the wall).
- **Nearer is absorbed slowly.** Where it lies nearer, something stands in front of the background: the
  background moves towards it with the time constant ``absorb_s`` (minutes), so an object put down and left
  becomes background after a few minutes, and a person who walks past changes nothing.
- **Tracked persons are never absorbed.** Pixels within the projected box of a confirmed track's joints (grown by
  ``keep_margin``) keep their background, however long the person stands there. A clinician who stands perfectly
  still for minutes stays in front of the background, and keeps their track.
- **Unknown** depth (0) changes nothing; the first known depth of a pixel is its background.

A person stands *where the static background is not* (:meth:`DepthBackground.foreground`) when most of their torso
joints that the depth images see (the depth at the joint's pixel within ``agree_mm`` of the joint: not hidden
behind something nearer) lie at least ``margin_mm`` in front of the background. The background starts as the
stream's first frame, so whoever is in it is background until they move (the tracker's other two cues).

Cost: the update and the question touch ``V x grid_width x grid_width * H / W`` pixels (3 x 80 x 60 here) and each
person's torso joints: about a millisecond per frame (``benchmarks/tracking.py --background``, its
``background_ms_mean``).

Usage::

    background = DepthBackground()
    fraction = background.foreground(joints, views)   # (P,) of each person's seen torso joints in front
    background.update(views, timestamp_s, keep=confirmed_joints)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from posenet.cameras import Camera
from posenet.scene import SceneView
from posenet.skeleton import JOINT_INDEX, NUM_JOINTS

# The joints inside a person's silhouette in every view (limbs' ends often land on what lies behind them).
TORSO = np.array([JOINT_INDEX[j] for j in ("head", "neck", "left_shoulder", "right_shoulder", "left_hip",
                                           "right_hip")])  # fmt: skip


@dataclass
class BackgroundConfig:
    # Columns of the coarse background: 80 x 60 for 4:3 views, where a person is at least 4 cells wide.
    grid_width: int = 80
    # A pixel this much nearer than the background is in front of it. Depth noise of the sensors rendered here is
    # a few cm at 4 m, and a person's torso is >= 20 cm in front of the wall or table behind it.
    margin_mm: float = 150.0
    reveal_rate: float = 0.5  # per frame, towards a farther depth: 5 frames take 97 % of the way
    # Time constant towards a nearer depth: a 1 m step falls below margin_mm in about 4 minutes.
    absorb_s: float = 120.0
    # The depth at a joint's pixel sees that joint when it lies within this of the joint's depth (a torso joint
    # lies 10-20 cm behind the body's surface); nearer, something hides the joint and says nothing of it.
    agree_mm: float = 350.0
    # A confirmed track's projected box grows by this share of its size on each side.
    keep_margin: float = 0.25


def _grid(depth: np.ndarray, step: int) -> np.ndarray:
    """``(h, w)`` float32 every ``step``-th pixel of ``depth (H, W)`` uint16 mm (0: unknown)."""
    return depth[step // 2 :: step, step // 2 :: step].astype(np.float32)


class _Rig:
    """The views' cameras as NumPy arrays, for projecting a few dozen points per frame without torch's per-call
    overhead: ``K (V, 4)`` fx, fy, cx, cy; ``R (V, 3, 3)``, ``t (V, 3)`` T(ref->v); ``dist (V, 5)`` or None."""

    def __init__(self, views: Sequence[SceneView]) -> None:
        cam = Camera.stack([v.camera for v in views]).to(dtype=torch.float64)
        to_cam = cam.ref_to_camera.numpy()
        self.K = cam.intrinsics.numpy()
        self.R, self.t = to_cam[:, :3, :3], to_cam[:, :3, 3]
        self.dist = None if cam.distortion is None else cam.distortion.numpy()
        self.key = self.key_of(views)

    @staticmethod
    def key_of(views: Sequence[SceneView]) -> bytes:
        return b"".join(
            v.camera.intrinsics.numpy().tobytes() + v.camera.extrinsics.numpy().tobytes() for v in views
        )

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``points (N, 3)`` mm, reference frame -> pixels ``(V, N, 2)`` (``posenet.cameras.Camera.project``'s
        model) and depth ``(V, N)`` mm along each camera's axis."""
        p = np.einsum("vij,nj->vni", self.R, points) + self.t[:, None]  # (V, N, 3)
        z = p[..., 2]
        x, y = p[..., 0] / np.maximum(z, 1e-6), p[..., 1] / np.maximum(z, 1e-6)
        if self.dist is not None:
            k1, k2, p1, p2, k3 = (self.dist[:, i, None] for i in range(5))
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
            )
        K = self.K[:, None]
        return np.stack([K[..., 0] * x + K[..., 2], K[..., 1] * y + K[..., 3]], -1), z


class DepthBackground:
    """Per camera, the static depth of a stream's room (module docstring). Views must keep their order and size
    over the stream; a frame with other sizes or another number of views starts the model again."""

    def __init__(self, config: BackgroundConfig | None = None) -> None:
        self.config = config or BackgroundConfig()
        self.depth: np.ndarray | None = None  # (V, h, w) float32 mm, 0: never seen
        self.step = 1
        self.time: float | None = None
        self._rig: _Rig | None = None
        self._now: tuple | None = None  # (the views' depth images, their grids (V, h, w)), read once a frame

    def _grids(self, views: Sequence[SceneView]) -> np.ndarray:
        """``(V, h, w)`` the views' depth on the grid, read once per frame."""
        depths = [v.depth for v in views]
        if (
            self._now is None
            or len(self._now[0]) != len(depths)
            or any(a is not b for a, b in zip(self._now[0], depths, strict=True))
        ):
            self._now = (depths, np.stack([_grid(d, self.step) for d in depths]))
        return self._now[1]

    def _cells(self, joints: np.ndarray, views: Sequence[SceneView]) -> tuple[np.ndarray, ...]:
        """Where ``joints (P, N, 3)`` (mm, reference frame) fall on the grid: ``row, col (V, P, N)`` int (clipped),
        ``z (V, P, N)`` mm along each camera's axis, and ``inside (V, P, N)`` bool (in front, in the image)."""
        if self._rig is None or self._rig.key != _Rig.key_of(views):
            self._rig = _Rig(views)
        P, N = joints.shape[:2]
        uv, z = self._rig.project(joints.reshape(P * N, 3))
        uv, z = uv.reshape(len(views), P, N, 2), z.reshape(len(views), P, N)
        h, w = self.depth.shape[1:]
        col = np.floor((uv[..., 0] + 0.5) / self.step).astype(int)
        row = np.floor((uv[..., 1] + 0.5) / self.step).astype(int)
        inside = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1), z, inside

    def _fits(self, views: Sequence[SceneView]) -> bool:
        if self.depth is None or len(views) != len(self.depth):
            return False
        h, w = self.depth.shape[1:]
        return all(_grid_shape(v.depth.shape, self.step) == (h, w) for v in views)

    def foreground(self, joints: np.ndarray, views: Sequence[SceneView]) -> np.ndarray:
        """``(P,)`` for each person of ``joints (P, J, 3)`` (mm, reference frame), the share of their torso joints
        seen in ``views``' depth that lie at least ``margin_mm`` in front of the background (NaN where no view sees
        one, or before the first :meth:`update`)."""
        joints = np.asarray(joints, float).reshape(-1, NUM_JOINTS, 3)
        P = len(joints)
        if not P or not self._fits(views):
            return np.full(P, np.nan)
        c = self.config
        row, col, z, inside = self._cells(joints[:, TORSO], views)  # (V, P, N) each
        v = np.arange(len(views))[:, None, None]
        seen, back = self._grids(views)[v, row, col], self.depth[v, row, col]  # (V, P, N); 0: unknown
        sees = inside & (seen > 0) & (np.abs(seen - z) <= c.agree_mm)
        front = sees & (back > 0) & (back - seen >= c.margin_mm)
        n = sees.sum((0, 2))
        return np.where(n > 0, front.sum((0, 2)) / np.maximum(n, 1), np.nan)

    def update(self, views: Sequence[SceneView], timestamp_s: float, keep: np.ndarray | None = None) -> None:
        """Learn from one frame's ``views`` at ``timestamp_s`` (s); ``keep (K, J, 3)``: the confirmed tracks'
        joints (mm, reference frame), whose pixels keep their background."""
        c = self.config
        if not self._fits(views):
            self.step = max(1, views[0].depth.shape[1] // c.grid_width)
            self._now = None
            self.depth = self._grids(views).copy()
            self.time = float(timestamp_s)
            self._now = None
            return
        dt = max(float(timestamp_s) - self.time, 0.0)
        self.time = float(timestamp_s)
        now, back = self._grids(views), self.depth
        known = now > 0
        absorb = -np.expm1(-dt / c.absorb_s)  # the share of the way towards a nearer depth in dt
        rate = np.where(now > back, np.float32(c.reveal_rate), np.float32(absorb))  # (V, h, w)
        if keep is not None and len(keep):  # where a confirmed person stands, only farther depths count
            rate[self._kept(np.asarray(keep, float).reshape(-1, NUM_JOINTS, 3), views) & (now < back)] = 0
        rate[back == 0] = 1.0  # the first known depth of a cell is its background
        back += np.where(known, rate * (now - back), 0)
        self._now = (
            None  # no images kept between frames: a stream's state may be stored (service.stream_store)
        )

    def _kept(self, joints: np.ndarray, views: Sequence[SceneView]) -> np.ndarray:
        """``(V, h, w)`` the cells within each person's projected joints' box, grown by ``keep_margin``."""
        row, col, _, inside = self._cells(joints, views)  # (V, K, J)
        h, w = self.depth.shape[1:]
        big = np.iinfo(int).max // 4
        r_lo, r_hi = np.where(inside, row, big).min(-1), np.where(inside, row, -big).max(-1)  # (V, K)
        q_lo, q_hi = np.where(inside, col, big).min(-1), np.where(inside, col, -big).max(-1)
        g = self.config.keep_margin
        dr, dq = g * (r_hi - r_lo + 1), g * (q_hi - q_lo + 1)  # negative for a person out of the view
        r, q = np.arange(h), np.arange(w)
        rows = (r >= (r_lo - dr)[..., None]) & (r < (r_hi + dr + 1)[..., None])  # (V, K, h)
        cols = (q >= (q_lo - dq)[..., None]) & (q < (q_hi + dq + 1)[..., None])  # (V, K, w)
        return (rows[..., :, None] & cols[..., None, :]).any(1)  # (V, h, w)


def _grid_shape(shape: tuple[int, ...], step: int) -> tuple[int, int]:
    """The shape :func:`_grid` gives an image of ``shape (H, W)``."""
    return len(range(step // 2, shape[0], step)), len(range(step // 2, shape[1], step))
