"""The renderer's cameras: a random ceiling-mounted RGB-D rig around the table, or MVOR's real rig.

A rig is :class:`posenet.rig.Rig`, the one camera rig of the project, whose reference frame here is the
renderer's world (z up, floor at z = 0): each camera's extrinsics are ``T(cam->world)``, its names the serial
numbers written into ``cameras_info``. The dataset's reference frame is camera 0's (``posenet.cameras``); MVOR's
``firstCamToRoomRef`` is ``T(cam0->room)``, and for the twin the world is MVOR's room frame shifted so that the
floor (found from the annotated poses) is at z = 0.

The renderer works in NumPy: :func:`intrinsics`, :func:`cam_to_world` and :func:`world_to_cam` read a rig's
cameras as its raster :class:`Intrinsics` and ``(V, 4, 4)`` arrays, and :func:`world_rig` builds a rig from them.
Float64 tensors hold the arrays' values exactly, so the pixels do not depend on the round trip.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from posenet.cameras import Camera
from posenet.rig.rigfile import Rig
from posenet.synth.raster import Intrinsics

KINECT = Intrinsics(538.0, 538.0, 320.0, 240.0)  # MVOR's Kinect-like cameras (fx ~ 535-541 px)
WORLD = "world (z up, floor at z = 0)"


def world_rig(intrinsics: Sequence[Intrinsics], cam_to_world: np.ndarray, serials: Sequence[str]) -> Rig:
    """A rig in the renderer's world: per camera its ``Intrinsics`` and ``cam_to_world (V, 4, 4)`` T(cam->world),
    mm; ``serials`` name the cameras."""
    if cam_to_world.shape != (len(intrinsics), 4, 4):
        raise ValueError(f"cam_to_world must be ({len(intrinsics)}, 4, 4), got {cam_to_world.shape}")
    cameras = [
        Camera.create(K.fx, K.fy, K.cx, K.cy, T.copy(), None, (int(K.width), int(K.height)))
        for K, T in zip(intrinsics, cam_to_world, strict=True)
    ]
    return Rig(cameras, list(serials), WORLD)


def intrinsics(rig: Rig) -> list[Intrinsics]:
    """One raster :class:`Intrinsics` per camera (distortion-free, as the renderer draws)."""
    return [Intrinsics(*c.intrinsics.tolist(), *c.size) for c in rig.cameras]


def cam_to_world(rig: Rig) -> np.ndarray:
    """(V, 4, 4) T(cam->world), mm: the rig's extrinsics."""
    return np.stack([c.extrinsics.numpy() for c in rig.cameras])


def world_to_cam(rig: Rig) -> np.ndarray:
    """(V, 4, 4) T(world->cam)."""
    return np.linalg.inv(cam_to_world(rig))


def look_at(position: np.ndarray, target: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """T(cam->world) (4, 4) of an OpenCV camera at ``position`` looking at ``target`` (world z up)."""
    z = target - position
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)  # image "down" points toward the floor
    c, s = np.cos(roll), np.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = position
    return T


def random_rig(
    rng: np.random.Generator,
    table_center: np.ndarray,
    half_extent: np.ndarray,
    num_views: int | None = None,
    serial_base: int = 0,
) -> Rig:
    """2 to 4 ceiling-mounted cameras spread around the table, 2.4-4.2 m from it, looking at it.

    The cameras are spread over about 250 degrees of azimuth (evenly, plus a random jitter), so that every
    person is seen from several sides as in MVOR; they are kept inside the room's shell.
    """
    V = int(rng.integers(2, 5)) if num_views is None else num_views
    if not 1 <= V <= 8:
        raise ValueError(f"num_views must be in 1..8, got {V}")
    base = rng.uniform(0, 2 * np.pi)
    offsets = np.sort(rng.uniform(0, 2 * np.pi, V))
    az = base + np.linspace(0, 2 * np.pi, V, endpoint=False) * 0.7 + offsets * 0.3 / max(V, 1)
    Ks, poses = [], []
    for a in az:
        dist = rng.uniform(2400, 4200)
        pos = table_center[:2] + dist * np.array([np.cos(a), np.sin(a)])
        lim = half_extent[:2] - 150
        pos = np.clip(pos, table_center[:2] - lim, table_center[:2] + lim)
        height = rng.uniform(2350, min(2850, 2 * half_extent[2] - 100))
        target = np.array([*(table_center[:2] + rng.uniform(-500, 500, 2)), rng.uniform(700, 1100)])
        poses.append(look_at(np.array([pos[0], pos[1], height]), target, rng.normal(0, 0.04)))
        Ks.append(Intrinsics(rng.normal(538, 4), rng.normal(538, 4), rng.normal(320, 5), rng.normal(241, 4)))
    serials = [f"synth-{serial_base + i:04d}" for i in range(V)]
    return world_rig(Ks, np.stack(poses), serials)


def mvor_rig(cameras_info: dict, floor_z: float) -> Rig:
    """MVOR's rig (distortion ignored, as MVOR's 3D annotations do) in its room frame with the floor at z =
    0."""
    params = cameras_info["camParams"]
    to_room = np.asarray(params["firstCamToRoomRef"], float).reshape(4, 4)
    shift = np.eye(4)
    shift[2, 3] = -floor_z
    Ks, poses = [], []
    for intr, ext in zip(params["intrinsics"], params["extrinsics"], strict=True):
        (fx, fy), (cx, cy) = intr["focallength"], intr["principalpoint"]
        w, h = intr.get("imagesize", (640, 480))
        Ks.append(Intrinsics(fx, fy, cx, cy, int(w), int(h)))
        poses.append(shift @ to_room @ np.asarray(ext, float).reshape(4, 4))
    serials = list(params.get("ids", [str(i) for i in range(len(Ks))]))
    return world_rig(Ks, np.stack(poses), serials)
