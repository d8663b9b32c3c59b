"""The MVOR-format reader: a dataset root plus its annotation json -> multi-view :class:`Sample`\\ s.

MVOR's schema (``camma_mvor_2018.json``; the renderer in ``posenet/synth`` writes the same, plus extra
keys that are ignored here):
- ``multiview_images[*]``: one synchronised frame, ``id`` (e.g. ``"10010000000_10020000000_10030000000"``) and
  its ``images`` (``file_name``, ``id``, ``cam_id`` 1-based, ``day_id``, ``width``, ``height``).
- ``annotations[*]``: one person box in one image: ``image_id``, ``bbox`` COCO ``[x, y, w, h]``, ``person_id``
  (-1 for boxes without an identity), ``keypoints`` (J x (u, v, flag)).
- ``annotations3D[*]``: one 3D pose, ``image_ids`` (the multi-view id), ``person_id``, ``keypoints3D`` (12 x
  (x, y, z, flag), mm). The points are in camera 0's frame whatever ``ref_camera`` says; the first 10 are the
  joints.
- ``cameras_info``: the calibration, read by :meth:`Camera.from_mvor` (intrinsics index = ``cam_id - 1``).

Pixel numbers in the json (boxes, 2D keypoints) are taken to be in the camera convention of
``posenet.cameras`` (origin at the centre of the top-left pixel), with no half-pixel shift: MVOR's 2D
keypoints agree with its own projections in that convention (``docs/CONVENTIONS.md``). Boxes become ``(x0, y0,
x1, y1) = (x, y, x + w, y + h)``.

Usage::

    ds = MvorDataset("/data/MVOR", "/data/MVOR/camma_mvor_2018.json", subsample=2, days=[1, 2, 3])
    sample = ds[0]                      # Sample with 3 views of 320x240
    for train_days, test_day in folds(ds.days): ...
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch

from posenet.boxes import coco_to_xyxy
from posenet.cameras import Camera, rescale_pixels
from posenet.data.images import depth_file_name, read_color, read_depth, subsample_color, subsample_depth
from posenet.data.sample import Sample, View
from posenet.data.support import boxes_per_person, pose_support
from posenet.skeleton import NUM_JOINTS

MODALITIES = ("color", "depth")
REQUIRED_KEYS = ("multiview_images", "annotations", "annotations3D", "cameras_info")
MVOR_DAYS = (1, 2, 3, 4)


def read_annotation_json(path: str | Path) -> dict:
    """The parsed annotation json at ``path`` (FileNotFoundError naming it when missing), not yet checked:
    :func:`load_annotations` checks MVOR's schema, ``detector.data`` the per-image part that it reads."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"annotation file {path} does not exist")
    with open(path) as f:
        return json.load(f)


def room_up(annotations: dict) -> np.ndarray | None:
    """The room's up direction, a unit (3,), in camera 0's frame (where MVOR's 3D poses lie): the z axis of MVOR's
    room frame, ``cameras_info.camParams.firstCamToRoomRef`` = T(cam0 -> room) (in the real file a standing
    person's head lies ~0.55 m above their hips along it). None when the file has no room frame."""
    params = annotations.get("cameras_info", {}).get("camParams", {})
    T = params.get("firstCamToRoomRef")
    if T is None:
        return None
    R = np.asarray(T, np.float64).reshape(4, 4)[:3, :3]
    up = R.T @ np.array([0.0, 0.0, 1.0])  # room z expressed in camera 0's axes
    return up / np.linalg.norm(up)


def load_annotations(path: str | Path, poses: bool = True) -> dict:
    """Read and check an MVOR-format annotation json (ValueError naming the file and the missing keys).

    ``poses=False`` drops ``annotations3D`` as soon as the file is parsed, and does not require it: for
    unlabelled recordings, and for the users that must never see 3D poses (``posenet.training.adapt``)."""
    gt = read_annotation_json(path)
    if not poses and isinstance(gt, dict):
        gt.pop("annotations3D", None)
    check_annotations(gt, str(path), poses)
    return gt


def check_annotations(gt: dict, source: str = "annotations", poses: bool = True) -> None:
    """Raise ValueError when ``gt`` lacks a key of MVOR's schema (``annotations3D`` only with ``poses``)."""
    if not isinstance(gt, dict):
        raise ValueError(f"{source}: expected a JSON object, got {type(gt).__name__}")
    missing = [k for k in REQUIRED_KEYS if k not in gt and (poses or k != "annotations3D")]
    if missing:
        raise ValueError(f"{source}: not an MVOR-format annotation file, missing keys {missing}")


def folds(days: Iterable[int] = MVOR_DAYS) -> list[tuple[tuple[int, ...], int]]:
    """The cross-validation folds: one per day, ``(train_days, test_day)`` with that day held out."""
    days = sorted(set(days))
    if len(days) < 2:
        raise ValueError(f"cross-validation needs at least two days, got {days}")
    return [(tuple(d for d in days if d != test), test) for test in days]


def check_reader_options(subsample, modalities: Sequence[str]) -> tuple[int, tuple[str, ...]]:
    """The ``subsample`` factor and ``modalities`` every reader takes, checked (ValueError naming the problem)."""
    if isinstance(subsample, bool) or int(subsample) != subsample or subsample < 1:
        raise ValueError(f"subsample must be a positive integer, got {subsample!r}")
    unknown = [m for m in modalities if m not in MODALITIES]
    if unknown:
        raise ValueError(f"unknown modalities {unknown}; choose from {MODALITIES}")
    return int(subsample), tuple(modalities)


def subsampled_camera(camera: Camera, factor: int) -> Camera:
    """The camera of its image subsampled by an integer ``factor`` (``Camera.scale``, size floored)."""
    if factor == 1:
        return camera
    size = camera.size
    # Blocks that do not fit are dropped (see images.py), hence the floor.
    small = None if size is None else (size[0] // factor, size[1] // factor)
    return dataclasses.replace(camera.scale(1.0 / factor), size=small)


def collate_samples(batch: Sequence[Sample]) -> list[Sample]:
    """DataLoader ``collate_fn``: samples differ in persons and boxes, so a batch stays a list."""
    return list(batch)


def _number_in(pattern: str, text: str) -> int | None:
    m = re.search(pattern, text)
    return int(m.group(1)) if m else None


def image_camera_index(image: dict, num_cameras: int) -> int:
    """The ``cameras_info`` index of an image: ``cam_id - 1`` (MVOR's cam1..cam3 are intrinsics 0..2)."""
    cam_id = image.get("cam_id", _number_in(r"cam(\d+)", image.get("file_name", "")))
    if cam_id is None or not 1 <= int(cam_id) <= num_cameras:
        raise ValueError(
            f"image {image.get('file_name', image.get('id'))!r}: unknown camera cam_id={cam_id}; "
            f"cameras_info describes {num_cameras} cameras (cam_id 1..{num_cameras})"
        )
    return int(cam_id) - 1


def image_day(image: dict) -> int:
    """The recording day of an image entry (``day_id``, or the ``dayD`` folder of its file name)."""
    day = image.get("day_id", _number_in(r"day(\d+)", image.get("file_name", "")))
    if day is None:
        raise ValueError(
            f"image {image.get('file_name', image.get('id'))!r} has no day_id and no dayD folder"
        )
    return int(day)


def _box_arrays(boxes: list[dict], image_name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K, 4) xyxy float32, (K,) int64 person ids, (K, J, 3) float32 keypoints of one image's annotations."""
    xywh = np.array([b["bbox"] for b in boxes], np.float64).reshape(-1, 4)  # (K, 4)
    if (xywh[:, 2:] < 0).any():
        raise ValueError(f"image {image_name!r}: a box has a negative width or height")
    xyxy = coco_to_xyxy(xywh)
    ids = np.array([b["person_id"] for b in boxes], np.int64)
    kps = np.zeros((len(boxes), NUM_JOINTS, 3), np.float32)
    for k, b in enumerate(boxes):
        flat = b.get("keypoints") or []
        if len(flat) >= NUM_JOINTS * 3:
            kps[k] = np.asarray(flat[: NUM_JOINTS * 3], np.float32).reshape(NUM_JOINTS, 3)
    return xyxy.astype(np.float32), ids, kps


def pose_joints(pose: dict, index: int) -> tuple[np.ndarray, np.ndarray]:
    """(J, 3) float64 joints (mm) and (J,) bool validity (flag > 0) of one ``annotations3D`` entry."""
    flat = np.asarray(pose["keypoints3D"], np.float64)
    if flat.size % 4 or flat.size < NUM_JOINTS * 4:
        raise ValueError(
            f"annotations3D[{index}] (id {pose.get('id')}): keypoints3D has {flat.size} numbers, "
            f"expected (x, y, z, flag) for at least {NUM_JOINTS} points"
        )
    points = flat.reshape(-1, 4)[:NUM_JOINTS]  # (J, 4)
    return points[:, :3], points[:, 3] > 0


@dataclasses.dataclass(frozen=True)
class _Frame:
    """Everything about one multi-view frame but its pixels (built once, when the dataset is made)."""

    id: str
    day: int
    views: list[
        tuple
    ]  # per view: (cam index, image entry, boxes (K, 4), person ids (K,), keypoints (K, J, 3))
    poses: np.ndarray  # (N, J, 3) float32
    valid: np.ndarray  # (N, J) bool
    person_ids: np.ndarray  # (N,) int64
    support: np.ndarray  # (N,) int64


class MvorDataset(torch.utils.data.Dataset):
    """Multi-view frames of an MVOR-format dataset as :class:`Sample`\\ s (see the module docstring).

    Args:
        root: the dataset folder holding ``dayD/camC/{color,depth}/NNNNNN.png``; None reads annotations only.
        annotations: the annotation json's path, or the already-loaded dict.
        subsample: integer factor; 2 gives the paper's 320x240 from 640x480 (cameras, boxes and 2D keypoints
            are scaled to match).
        modalities: which images to load, a subset of ``("color", "depth")``; ``()`` reads annotations only.
        days: the recording days to keep (None keeps all).
        poses: False never reads ``annotations3D`` (a loaded dict must not hold them; a path is loaded without
            them): every sample then has no 3D pose. For recordings without 3D poses, and for ``posenet.training.adapt``,
            which must never see them.
    """

    def __init__(
        self,
        root: str | Path | None,
        annotations: str | Path | dict,
        subsample: int = 1,
        modalities: Sequence[str] = MODALITIES,
        days: Iterable[int] | None = None,
        poses: bool = True,
    ) -> None:
        if isinstance(annotations, dict):
            check_annotations(annotations, poses=poses)
            if not poses and "annotations3D" in annotations:
                raise ValueError(
                    "poses=False, but the annotation dict holds annotations3D: load it with "
                    "load_annotations(path, poses=False)"
                )
            self.annotations = annotations
        else:
            self.annotations = load_annotations(annotations, poses)
        self.poses = poses
        self.subsample, modalities = check_reader_options(subsample, modalities)
        self.modalities = modalities if root is not None else ()
        self.root = None if root is None else Path(root)
        if self.root is not None and self.modalities and not self.root.is_dir():
            raise FileNotFoundError(f"dataset root {self.root} is not a folder")

        self.cameras = Camera.from_mvor(self.annotations["cameras_info"])
        self.up = room_up(self.annotations)
        self._frames = self._index(self.annotations)
        all_days = sorted({f.day for f in self._frames})
        if days is not None:
            days = sorted(set(int(d) for d in days))
            missing = [d for d in days if d not in all_days]
            if missing:
                raise ValueError(f"days {missing} have no frames; the annotations hold days {all_days}")
            self._frames = [f for f in self._frames if f.day in days]
        self.days = sorted({f.day for f in self._frames})

    # ----------------------------------------------------------------- indexing
    def _index(self, gt: dict) -> list[_Frame]:
        """Everything but the pixels, per frame, in ``multiview_images`` order."""
        boxes_by_image = defaultdict(list)
        for box in gt["annotations"]:
            boxes_by_image[box["image_id"]].append(box)
        poses_by_frame = defaultdict(list)
        if self.poses:
            support = pose_support(gt, boxes_per_person(gt["annotations"]))
            for i, pose in enumerate(gt["annotations3D"]):
                poses_by_frame[pose["image_ids"]].append((i, pose, support[i]))

        frames = []
        n_cams = len(self.cameras)
        for mv in gt["multiview_images"]:
            views = []
            for image in mv["images"]:
                cam = image_camera_index(image, n_cams)
                name = image.get("file_name", str(image["id"]))
                views.append((cam, image, *_box_arrays(boxes_by_image.get(image["id"], []), name)))
            views.sort(key=lambda v: v[0])  # cameras_info order
            if len({v[0] for v in views}) != len(views):
                raise ValueError(f"multi-view frame {mv['id']!r} lists the same camera twice")
            poses = poses_by_frame.get(mv["id"], [])
            joints = np.zeros((len(poses), NUM_JOINTS, 3), np.float32)
            valid = np.zeros((len(poses), NUM_JOINTS), bool)
            for k, (i, pose, _) in enumerate(poses):
                joints[k], valid[k] = pose_joints(pose, i)
            frames.append(
                _Frame(
                    id=mv["id"],
                    day=image_day(mv["images"][0]),
                    views=views,
                    poses=joints,
                    valid=valid,
                    person_ids=np.array([p["person_id"] for _, p, _ in poses], np.int64),
                    support=np.array([s for _, _, s in poses], np.int64),
                )
            )
        return frames

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def ids(self) -> list[str]:
        """The multi-view ids of the kept frames, in dataset order."""
        return [f.id for f in self._frames]

    # ----------------------------------------------------------------- reading
    def _full_size(self, cam: int, image: dict) -> tuple[int, int] | None:
        """(width, height) of a view's files: the image entry's, else the calibration's ``imagesize``."""
        if "width" in image and "height" in image:
            return int(image["width"]), int(image["height"])
        return self.cameras[cam].size

    def _camera(self, cam: int, size: tuple[int, int] | None) -> Camera:
        return subsampled_camera(dataclasses.replace(self.cameras[cam], size=size), self.subsample)

    def _view(self, cam: int, image: dict, boxes: np.ndarray, ids: np.ndarray, kps: np.ndarray) -> View:
        size = self._full_size(cam, image)
        camera = self._camera(cam, size)
        color = depth = None
        if "color" in self.modalities:
            color = subsample_color(read_color(self.root / image["file_name"], size), self.subsample)
        if "depth" in self.modalities:
            depth = subsample_depth(
                read_depth(self.root / depth_file_name(image["file_name"]), size), self.subsample
            )
        if self.subsample > 1:
            boxes = rescale_pixels(boxes, 1 / self.subsample)
            kps = kps.copy()
            annotated = kps[..., 2] > 0  # unannotated keypoints stay at (0, 0, 0)
            kps[..., :2] = np.where(annotated[..., None], rescale_pixels(kps[..., :2], 1 / self.subsample), 0)
        return View(
            camera=camera,
            color=color,
            depth=depth,
            boxes=boxes.astype(np.float32),
            box_person_ids=ids.copy(),
            image_id=image["id"],
            file_name=image["file_name"],
            cam_index=cam,
            keypoints2d=kps.astype(np.float32),
        )

    def __getitem__(self, index: int) -> Sample:
        frame = self._frames[index]
        return Sample(
            id=frame.id,
            day=frame.day,
            views=[self._view(*v) for v in frame.views],
            poses=frame.poses.copy(),
            valid=frame.valid.copy(),
            person_ids=frame.person_ids.copy(),
            support=frame.support.copy(),
            up=None if self.up is None else self.up.copy(),
        )
