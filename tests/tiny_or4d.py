"""A tiny dataset in 4D-OR's layout and schema (``posenet/data/or4d.py``'s docstring), written by the tests.

2 takes x 3 frame entries x 6 cameras at 160x120 on a ring of ceiling cameras (4D-OR's camera json: y-up/z-back
frames, metres, quaternions, a colour-to-depth offset). Frames 0 and 1 of each take are annotated with two people
("Patient" and "human_0", 14 named joints in the annotation tool's frame; human_0 has no right foot in frame 1);
frame 2 has no annotation file. Colour indices differ from the point-cloud index, as in 4D-OR.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

WIDTH, HEIGHT = 160, 120
N_CAMERAS = 6
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _pose_json(T: np.ndarray) -> dict:
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return {
        "translation": {"m00": T[0, 3], "m10": T[1, 3], "m20": T[2, 3]},
        "rotation": {"x": x, "y": y, "z": z, "w": w},
    }


def camera_to_world(index: int, n: int) -> np.ndarray:
    """(4, 4) OpenCV camera -> world (metres, z up) of camera ``index`` on a 3 m ring at 2.6 m, aimed at the table."""
    a = 2 * np.pi * index / n + 0.3
    position = np.array([3.0 * np.cos(a), 3.0 * np.sin(a), 2.6])
    forward = np.array([0.2 * np.sin(index), 0.0, 1.0]) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    T = np.eye(4)
    T[:3, :3] = np.stack([right, np.cross(forward, right), forward], 1)
    T[:3, 3] = position
    return T


def write_camera_json(
    path: Path, rng: np.random.Generator, index: int, n: int = N_CAMERAS
) -> tuple[np.ndarray, np.ndarray]:
    """Write ``camera0N.json``; returns 4D-OR's ``camera_pose`` and ``color2depth_transform`` (4x4, metres)."""
    colour_gl = camera_to_world(index, n) @ GL_TO_CV  # 4D-OR's colour frame: y up, z back
    c2d = np.eye(4)
    c2d[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix()
    c2d[:3, 3] = [-0.032, 0.002, 0.004]
    pose = colour_gl @ np.linalg.inv(c2d)
    fx, cx, cy = 118.0 + index, 79.5 + rng.normal(0, 1), 59.5 + rng.normal(0, 1)
    cp = {"fov_x": fx, "fov_y": fx + 0.3, "c_x": cx, "c_y": cy, "width": WIDTH, "height": HEIGHT,
          "intrinsics_matrix": {"m00": fx, "m10": 0.0, "m20": cx, "m01": 0.0, "m11": fx + 0.3, "m21": cy,
                                "m02": 0.0, "m12": 0.0, "m22": 1.0},
          "radial_distortion": {f"m{k}0": 0.0 for k in range(6)}, "tangential_distortion": {"m00": 0.0, "m10": 0.0}}  # fmt: skip
    value = {
        "color_parameters": cp,
        "camera_pose": _pose_json(pose),
        "color2depth_transform": _pose_json(c2d),
    }
    path.write_text(json.dumps({"value0": value}))
    return pose, c2d


# 14 joints (4D-OR's order) as (left, forward, up) offsets from the neck, mm.
OFFSETS = [(0, 0, 230), (0, 0, 0), (180, 0, -30), (-180, 0, -30), (110, 0, -520), (-110, 0, -520),
           (230, 40, -300), (-230, 40, -300), (200, 220, -480), (-200, 220, -480),
           (110, 30, -950), (-110, 30, -950), (110, 60, -1400), (-110, 60, -1400)]  # fmt: skip
NAMES = ["head", "neck", "leftshoulder", "rightshoulder", "lefthip", "righthip", "leftelbow", "rightelbow",
         "leftwrist", "rightwrist", "leftknee", "rightknee", "leftfoot", "rightfoot"]  # fmt: skip


def person_mm(rng: np.random.Generator) -> np.ndarray:
    """(14, 3) joints of a standing person in the world (mm, z up) near the table."""
    neck = np.array([rng.uniform(-400, 400), rng.uniform(-400, 400), 1450.0])
    a = rng.uniform(0, 2 * np.pi)
    left, fwd = np.array([np.cos(a), np.sin(a), 0]), np.array([-np.sin(a), np.cos(a), 0])
    return np.array([neck + l * left + f * fwd + u * np.array([0, 0, 1.0]) for l, f, u in OFFSETS])


def mm_to_tool(points_mm: np.ndarray) -> np.ndarray:
    """World mm -> the annotation tool's frame: the inverse of 4D-OR's (25 x, 25 z + 1000, -25 y), x500 space."""
    X, Y, Z = (points_mm / 2.0).T  # x500 space: metres x 500
    return np.stack([X / 25, -Z / 25, (Y - 1000) / 25], -1)


def write_tiny_or4d(root: Path, takes=(1, 2), seed: int = 0) -> dict:
    """Write the dataset under ``root``; returns ``{take: {"poses": [(2, 14, 3) mm world per annotated frame]}}``."""
    rng = np.random.default_rng(seed)
    truth = {}
    for take in takes:
        folder = root / f"export_holistic_take{take}_processed"
        (folder / "annotations").mkdir(parents=True)
        (folder / "colorimage").mkdir()
        (folder / "depthimage").mkdir()
        for i in range(N_CAMERAS):
            write_camera_json(folder / f"camera{i + 1:02d}.json", rng, i)
        index, poses = [], []
        for frame in range(3):
            channels = {"pcd": f"{frame:06d}"}
            for c in range(1, N_CAMERAS + 1):
                channels[f"color_{c}"] = channels[f"depth_{c}"] = f"{frame * 3 + 7:06d}"
                color = np.full((HEIGHT, WIDTH, 3), (40 * c, 90, 200 - 20 * c), np.uint8)
                depth = np.full((HEIGHT, WIDTH), 3000 + 10 * frame, np.uint16)
                depth[:4] = 0
                cv2.imwrite(
                    str(folder / f"colorimage/camera{c:02d}_colorimage-{channels[f'color_{c}']}.jpg"), color
                )
                cv2.imwrite(
                    str(folder / f"depthimage/camera{c:02d}_depthimage-{channels[f'depth_{c}']}.tiff"), depth
                )
            index.append([f"2021-0{take}-01T10:00:0{frame}", channels])
            if frame == 2:
                continue  # a frame without annotations
            people = np.stack([person_mm(rng), person_mm(rng)])
            poses.append(people)
            labels = []
            for name, joints in zip(["human_0", "Patient"], people[::-1], strict=True):
                for jname, p in zip(NAMES, mm_to_tool(joints), strict=True):
                    if name == "human_0" and frame == 1 and jname == "rightfoot":
                        continue
                    labels.append({"humanName": name, "jointName": jname,
                                   "point3d": {"location": {"x": p[0], "y": p[1], "z": p[2]}}})  # fmt: skip
            (folder / f"annotations/{channels['pcd']}.json").write_text(json.dumps({"labels": labels}))
        (folder / "timestamp_to_pcd_and_frames_list.json").write_text(json.dumps(index))
        truth[take] = {"poses": poses}  # per frame: [Patient, human_0] (sorted names)
    return truth
