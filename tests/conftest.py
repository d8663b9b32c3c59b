"""Shared test fixtures: MVOR's real calibration, the real annotation file (when present) and a tiny dataset.

- ``MVOR_CAMERAS_INFO``: the ``cameras_info`` block of MVOR's three cameras (calibration numbers from
  ``camma_mvor_2018.json``, CC BY-NC-SA 4.0, Srivastav et al., MICCAI-LABELS 2018), so camera tests run
  without the annotation file. ``test_mvor.py`` checks it against the file when the file is there.
- ``mvor_json`` / ``mvor_annotations``: the real annotation file at ``<repo>/../shared/mvor/``; tests that use
  them skip with the reason when it is absent.
- ``tiny_mvor_dataset``: a dataset in MVOR's layout and schema, written into the test's ``tmp_path``
  (``write_tiny_mvor`` for other folders or sizes). 2 days x 2 frames x 3 cameras at 640x480 on the real MVOR
  rig: colour PNGs with simple shapes, real 16-bit depth PNGs, boxes, 2D keypoints and 3D poses that agree
  with the cameras (the 2D keypoints are exact projections of the 3D joints).

Frame ``f`` of every day holds two persons: person 0 is boxed in all three views; person 1 is boxed in cameras
1 and 2 in frame 0 (support 2) and only in camera 1 in frame 1 (support 1), with its right wrist unannotated
(flag 0) there. Camera 2 also holds one box without identity (``person_id`` -1, ``only_bbox``) in every frame.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

REPO_ROOT = Path(__file__).resolve().parents[1]
MVOR_JSON = REPO_ROOT.parent / "shared" / "mvor" / "camma_mvor_2018.json"

MVOR_CAMERAS_INFO = {
    "camParams": {
        "firstCamToRoomRef": [
            -0.014959075298595706, -0.570907470567468, 0.8208781189168504, -1955.1484101018448,
            -0.9944440530407923, 0.09404781357538733, 0.04728672259197974, 880.9559188200409,
            -0.10419813548241928, -0.815609997984297, -0.5691424072673225, 1470.1399129239926,
            0, 0, 0, 1,
        ],
        "intrinsics": [
            {"serialnumber": "3210-1205220174", "skew_value": 0,
             "distortion": [0.2788, -1.2543, 6.459, -0.0, 0.0007],
             "principalpoint": [315.8367, 241.9166], "focallength": [538.597, 538.2393],
             "imagesize": [640, 480]},
            {"serialnumber": "33210-1208130014", "skew_value": 0,
             "distortion": [0.0197, -0.0508, 0.3164, -0.0001, 0.0006],
             "principalpoint": [321.2326, 243.3514], "focallength": [534.8386, 534.4008],
             "imagesize": [640, 480]},
            {"serialnumber": "32101-1208270248", "skew_value": 0,
             "distortion": [0.0267, -1.6653, 13.3344, -0.0025, 0.0002],
             "principalpoint": [323.9545, 238.6629], "focallength": [541.4062, 540.5641],
             "imagesize": [640, 480]},
        ],
        "ids": ["1205220174", "1208130014", "1208270248"],
        "extrinsics": [
            [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
            [-0.9827532061654909, 0.04488368874450566, 0.17939228036940189, -496.2376185870553,
             0.1848305389349967, 0.26891529014386256, 0.9452630525963875, -2260.755645548191,
             -0.005814434490689473, 0.9621174674703332, -0.27257323995584165, 3156.004317369521, 0, 0, 0, 1],
            [0.3285373775045781, -0.5371821653378832, 0.7768516671960721, -2495.61272184281,
             0.542788750504468, 0.7805020660063311, 0.3101562465687994, -639.2777808976291,
             -0.7729447353518953, 0.31976842590029225, 0.5480005382196593, 908.3081896399808, 0, 0, 0, 1],
        ],
    },
    "date_identifier": "20150331",
}  # fmt: skip

MVOR_CATEGORY = {
    "id": "1",
    "name": "person",
    "supercategory": "person",
    "keypoints": ["head", "neck", "left_shoulder", "right_shoulder", "left_hip", "right_hip",
                  "left_elbow", "right_elbow", "left_wrist", "right_wrist"],
    "skeleton": [[1, 2], [2, 4], [4, 8], [4, 6], [8, 10], [2, 3], [3, 5], [3, 7], [7, 9], [5, 6]],
}  # fmt: skip

WIDTH, HEIGHT = 640, 480


@pytest.fixture(scope="session")
def mvor_json() -> Path:
    """Path of the real MVOR annotation file; skips the test when it is absent."""
    if not MVOR_JSON.is_file():
        pytest.skip(f"the real MVOR annotation file is not at {MVOR_JSON} (../shared/mvor/ beside the repo)")
    return MVOR_JSON


@pytest.fixture(scope="session")
def mvor_annotations(mvor_json: Path) -> dict:
    """The real MVOR annotation dict, loaded once per session (do not modify it)."""
    with open(mvor_json) as f:
        return json.load(f)


# --------------------------------------------------------------------------- the tiny dataset
class TinyMvor(NamedTuple):
    root: Path  # dataset root: dayD/camC/{color,depth}/NNNNNN.png
    annotations: Path  # root / "annotations.json"
    gt: dict  # the annotation dict written there


def _rig() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(3, 3, 3) K, (3, 4, 4) T(ref->v), (4, 4) T(room->ref) of MVOR's cameras, undistorted (as MVOR)."""
    p = MVOR_CAMERAS_INFO["camParams"]
    K = np.zeros((len(p["intrinsics"]), 3, 3))
    K[:, [0, 1], [0, 1]] = [i["focallength"] for i in p["intrinsics"]]
    K[:, [0, 1], [2, 2]] = [i["principalpoint"] for i in p["intrinsics"]]
    K[:, 2, 2] = 1
    to_cam = np.linalg.inv(np.array(p["extrinsics"], np.float64).reshape(-1, 4, 4))
    room_to_ref = np.linalg.inv(np.array(p["firstCamToRoomRef"], np.float64).reshape(4, 4))
    return K, to_cam, room_to_ref


def _project(K: np.ndarray, to_cam: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project (J, 3) reference-frame points into one camera: (J, 2) pixels and (J,) depths."""
    cam = points @ to_cam[:3, :3].T + to_cam[:3, 3]
    uvw = cam @ K.T
    return uvw[:, :2] / uvw[:, 2:], cam[:, 2]


def _pose_in_room(rng: np.random.Generator) -> np.ndarray:
    """A standing upper body (J, 3) in the room frame (z up, mm), random place and heading."""
    neck = np.array([rng.uniform(-100, 600), rng.uniform(700, 1200), rng.uniform(380, 480)])
    a = rng.uniform(0, 2 * np.pi)
    left, fwd, up = (
        np.array([np.cos(a), np.sin(a), 0]),
        np.array([-np.sin(a), np.cos(a), 0]),
        np.array([0, 0, 1.0]),
    )
    offsets = [  # (left, forward, up) from the neck: arms bent forward, as a surgeon's
        (0, 0, 230), (0, 0, 0), (180, 0, -30), (-180, 0, -30), (110, 0, -520), (-110, 0, -520),
        (230, 40, -300), (-230, 40, -300), (200, 220, -480), (-200, 220, -480),
    ]  # fmt: skip
    return np.array([neck + l * left + f * fwd + u * up for l, f, u in offsets])


def _person_in_view(rng: np.random.Generator, room_to_ref, K, to_cam, margin: float = 25.0) -> np.ndarray:
    """A pose (J, 3) in the reference frame whose joints project inside every image with ``margin`` pixels."""
    for _ in range(1000):
        room = _pose_in_room(rng)
        ref = room @ room_to_ref[:3, :3].T + room_to_ref[:3, 3]
        uvs = [_project(K[v], to_cam[v], ref)[0] for v in range(len(K))]
        if all(((uv >= margin) & (uv <= [WIDTH - 1 - margin, HEIGHT - 1 - margin])).all() for uv in uvs):
            return ref
    raise RuntimeError("could not place a person inside all three MVOR views")


def _box(uv: np.ndarray) -> list[float]:
    """COCO [x, y, w, h] around projected joints, padded and clipped to the image."""
    x0, y0 = np.maximum(uv.min(axis=0) - 20, 0)
    x1, y1 = np.minimum(uv.max(axis=0) + 20, [WIDTH - 1, HEIGHT - 1])
    return [float(x0), float(y0), float(x1 - x0), float(y1 - y0)]


def _box_annotation(
    gt: dict, image_id: int, person_id: int, bbox: list, keypoints: list | None = None
) -> dict:
    """One MVOR ``annotations`` entry; a box without keypoints is MVOR's ``only_bbox``."""
    return {
        "id": len(gt["annotations"]),
        "image_id": image_id,
        "category_id": "1",
        "person_id": person_id,
        "bbox": bbox,
        "keypoints": keypoints or [0.0] * 30,
        "only_bbox": int(keypoints is None),
        "person_role": "clinician",
        "face_blurred": 0,
    }


def write_tiny_mvor(root: Path, days=(1, 2), frames_per_day: int = 2, seed: int = 0) -> TinyMvor:
    """Write a tiny MVOR-format dataset under ``root`` (see the module docstring) and return its paths."""
    rng = np.random.default_rng(seed)
    K, to_cam, room_to_ref = _rig()
    gt = {
        "info": {"description": "tiny MVOR-format test dataset"},
        "renderer_info": {"note": "an extra key, which readers must ignore"},
        "categories": [MVOR_CATEGORY],
        "cameras_info": MVOR_CAMERAS_INFO,
        "multiview_images": [],
        "images": [],
        "annotations": [],
        "annotations3D": [],
    }
    for day in days:
        for frame in range(frames_per_day):
            poses = [_person_in_view(rng, room_to_ref, K, to_cam) for _ in range(2)]
            flags = np.full((2, 10), 2.0)
            boxed = [
                (0, 1, 2),
                (0, 1) if frame % 2 == 0 else (0,),
            ]  # views (0-based) where each person has a box
            if frame % 2 == 1:
                flags[1, 9] = 0  # person 1's right wrist is unannotated here
            images = []
            for v in range(3):
                image_id = day * 10**10 + (v + 1) * 10**7 + frame
                name = f"day{day}/cam{v + 1}/color/{frame:06d}.png"
                images.append({"id": image_id, "file_name": name, "cam_id": v + 1, "day_id": day,
                               "width": WIDTH, "height": HEIGHT})  # fmt: skip
                color = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
                color[..., 0] = np.linspace(40, 120, WIDTH, dtype=np.uint8)[None]  # a wall with a gradient
                color[..., 1] = 60 + 30 * v
                depth = np.tile(np.linspace(3200, 3900, WIDTH).astype(np.uint16), (HEIGHT, 1))
                depth[:, :12] = 0  # the sensor's invalid border
                order = np.argsort([-_project(K[v], to_cam[v], p)[1].mean() for p in poses])  # far to near
                for p in order.tolist():
                    uv, z = _project(K[v], to_cam[v], poses[p])
                    if v not in boxed[p]:
                        continue  # occluded in this view: no box, not drawn
                    x, y, w, h = _box(uv)
                    colour = (200, 60, 60) if p == 0 else (60, 60, 220)
                    cv2.rectangle(color, (int(x), int(y)), (int(x + w), int(y + h)), colour, -1)
                    depth[int(y) : int(y + h) + 1, int(x) : int(x + w) + 1] = int(np.median(z))
                    for u, vv in uv:
                        cv2.circle(color, (int(round(u)), int(round(vv))), 4, (250, 250, 90), -1)
                    kps = np.concatenate([uv, flags[p][:, None]], axis=1)
                    kps[flags[p] == 0] = 0
                    gt["annotations"].append(
                        _box_annotation(gt, image_id, p, [x, y, w, h], kps.ravel().tolist())
                    )
                if v == 1:  # a person without identity at the image border
                    gt["annotations"].append(_box_annotation(gt, image_id, -1, [560.0, 200.0, 79.0, 200.0]))
                    cv2.rectangle(color, (560, 200), (639, 400), (90, 200, 90), -1)
                    depth[200:401, 560:640] = 2500
                for folder, image in (("color", cv2.cvtColor(color, cv2.COLOR_RGB2BGR)), ("depth", depth)):
                    path = root / f"day{day}/cam{v + 1}/{folder}/{frame:06d}.png"
                    path.parent.mkdir(parents=True, exist_ok=True)
                    cv2.imwrite(str(path), image)
            mv_id = "_".join(str(im["id"]) for im in images)
            gt["multiview_images"].append({"id": mv_id, "images": images})
            gt["images"] += images
            for p, pose in enumerate(poses):
                points = np.concatenate([pose, flags[p][:, None]], axis=1)  # (J, 4)
                points[flags[p] == 0, :3] = 0
                hands = np.concatenate(
                    [pose[8:10] + [0, 0, -90], np.full((2, 1), 1.0)], axis=1
                )  # unused extras
                gt["annotations3D"].append(
                    {"id": str(len(gt["annotations3D"])), "image_ids": mv_id, "person_id": p, "ref_camera": 0,
                     "keypoints3D": np.concatenate([points, hands]).ravel().tolist()}
                )  # fmt: skip
    path = root / "annotations.json"
    with open(path, "w") as f:
        json.dump(gt, f)
    return TinyMvor(root, path, gt)


@pytest.fixture
def tiny_mvor_dataset(tmp_path: Path) -> TinyMvor:
    """A fresh tiny MVOR-format dataset in this test's ``tmp_path`` (tests may modify it)."""
    return write_tiny_mvor(tmp_path / "tiny_mvor")
