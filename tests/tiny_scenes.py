"""A tiny renderer of MVOR-format datasets for the pose-network tests: spheres on a skeleton, seen by 3
cameras.

Each joint (and each bone's midpoint) is a sphere of 90 mm, coloured by its joint, in front of a wall, seen by
three 80x60 RGB-D cameras around the scene. The files and the json follow MVOR's layout and schema, so the
real
reader (``posenet.data.mvor``) reads them. Deterministic for a given seed.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from posenet.skeleton import BONES, JOINT_COLOURS

SIZE = (80, 60)
FOCAL = 75.0
TEMPLATE = np.array(
    [[0, -700, 0], [0, -550, 0], [180, -500, 0], [-180, -500, 0], [120, 0, 0], [-120, 0, 0],
     [250, -260, 40], [-250, -260, 40], [270, -60, 160], [-270, -60, 160]], np.float64,
)  # fmt: skip


def rig() -> list[np.ndarray]:
    """T(v->0) of three cameras looking at (0, 0, 3000) from -50, 0 and +50 degrees."""
    target = np.array([0.0, 0.0, 3000.0])
    out = []
    for deg in (0.0, 50.0, -50.0):
        a = np.deg2rad(deg)
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = target - R[:, 2] * 3000.0
        out.append(T)
    return out


def random_pose(rng: np.random.Generator) -> np.ndarray:
    a = rng.uniform(-0.6, 0.6)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    pose = TEMPLATE + rng.normal(0, 30, TEMPLATE.shape) * (np.arange(10) >= 6)[:, None]
    return pose @ R.T + np.array([rng.uniform(-300, 300), rng.uniform(-100, 100), rng.uniform(2700, 3300)])


def render(poses: list[np.ndarray], T: np.ndarray, rng: np.random.Generator):
    """Colour (H, W, 3) uint8, depth (H, W) uint16 and per-person boxes (xyxy or None) of one camera."""
    W, H = SIZE
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - (W - 1) / 2) / FOCAL, (v - (H - 1) / 2) / FOCAL, np.ones_like(u)], -1).reshape(
        -1, 3
    )
    depth = np.full(H * W, 4500.0)
    owner = np.full(H * W, -1)
    color = np.full((H * W, 3), 90.0) + rng.normal(0, 8, (H * W, 3))
    Tinv = np.linalg.inv(T)
    for p, pose in enumerate(poses):
        centres = np.concatenate([pose, [(pose[a] + pose[b]) / 2 for a, b in BONES]])  # (S, 3)
        colours = np.concatenate([JOINT_COLOURS, [JOINT_COLOURS[a] for a, _ in BONES]]).astype(np.float64)
        c = centres @ Tinv[:3, :3].T + Tinv[:3, 3]  # camera frame
        dc = rays @ c.T  # (N, S)
        dd = (rays**2).sum(1, keepdims=True)
        disc = dc**2 - dd * ((c**2).sum(1) - 90.0**2)
        t = np.where(disc > 0, (dc - np.sqrt(np.clip(disc, 0, None))) / dd, np.inf)
        s = t.argmin(1)
        hit = t[np.arange(len(t)), s]
        closer = hit < depth
        depth = np.where(closer, hit, depth)
        owner = np.where(closer, p, owner)
        color[closer] = colours[s[closer]]
    depth[rng.random(H * W) < 0.03] = 0
    boxes = []
    for p in range(len(poses)):
        ys, xs = np.nonzero((owner == p).reshape(H, W))
        boxes.append(
            None if len(xs) < 4 else [float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())]
        )
    return color.clip(0, 255).astype(np.uint8).reshape(H, W, 3), depth.astype(np.uint16).reshape(H, W), boxes


def write_dataset(root: Path, frames_per_day: dict[int, int], persons: int = 1, seed: int = 0) -> Path:
    """Write ``root/dayD/camC/{color,depth}/NNNNNN.png`` and ``root/annotations.json``; return the json
    path."""
    rng = np.random.default_rng(seed)
    Ts = rig()
    W, H = SIZE
    gt = {
        "multiview_images": [],
        "annotations": [],
        "annotations3D": [],
        "cameras_info": {
            "camParams": {
                "intrinsics": [
                    {
                        "focallength": [FOCAL, FOCAL],
                        "principalpoint": [(W - 1) / 2, (H - 1) / 2],
                        "imagesize": [W, H],
                    }
                ]
                * 3,
                "extrinsics": [T.reshape(-1).tolist() for T in Ts],
            }
        },
    }
    for day, n in frames_per_day.items():
        for f in range(n):
            poses = [random_pose(rng) for _ in range(persons)]
            ids = [day * 10**9 + (c + 1) * 10**7 + f for c in range(3)]
            mv = {"id": "_".join(map(str, ids)), "images": []}
            for c, T in enumerate(Ts):
                color, depth, boxes = render(poses, T, rng)
                name = f"day{day}/cam{c + 1}/color/{f:06d}.png"
                for kind, img in (("color", cv2.cvtColor(color, cv2.COLOR_RGB2BGR)), ("depth", depth)):
                    path = root / name.replace("/color/", f"/{kind}/")
                    path.parent.mkdir(parents=True, exist_ok=True)
                    cv2.imwrite(str(path), img)
                mv["images"].append(
                    {"file_name": name, "id": ids[c], "cam_id": c + 1, "day_id": day, "width": W, "height": H}
                )
                for p, b in enumerate(boxes):
                    if b is not None:
                        box = [b[0], b[1], b[2] - b[0], b[3] - b[1]]
                        gt["annotations"].append(
                            {"image_id": ids[c], "bbox": box, "person_id": p, "id": len(gt["annotations"])}
                        )
            gt["multiview_images"].append(mv)
            for p, pose in enumerate(poses):
                kp = np.concatenate([pose, np.ones((10, 1)) * 2], 1).reshape(-1).tolist() + [0.0] * 8
                gt["annotations3D"].append(
                    {"image_ids": mv["id"], "person_id": p, "keypoints3D": kp, "ref_camera": 0}
                )
    path = root / "annotations.json"
    path.write_text(json.dumps(gt))
    return path
