"""The unlabelled target of ``detector.adapt``: synchronised multi-view RGB-D frames, held in memory at the
detector's input size, with their cameras and each camera's static depth.

Only the frames (``multiview_images``: image ids, file names, cameras, days) and the calibration
(``cameras_info``) of the annotation file are read; its boxes (``annotations``) and poses (``annotations3D``)
are dropped as it is parsed, so a recording without any label adapts the same way (the weights are bit-identical,
``tests/detector/test_adapt.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from detector.data import ImageRecord, read_record
from detector.inputs import resize_factor, resize_view
from detector.model import DetectorConfig
from posenet.cameras import Camera
from posenet.data.mvor import image_camera_index, image_day, read_annotation_json

# What detector.adapt reads of an annotation file: the frames and the calibration, never a label.
READ_KEYS = ("multiview_images", "cameras_info")


def read_frames_and_cameras(path: str | Path) -> dict:
    """The ``multiview_images`` and ``cameras_info`` of an MVOR-format file (everything else is dropped)."""
    data = read_annotation_json(path)
    missing = [k for k in READ_KEYS if k not in data]
    if missing:
        raise ValueError(
            f"{path} has no {missing}: detector.adapt needs MVOR's multi-view frames and camera calibration "
            "(posenet.rig converts other calibrations; docs/detector.md)"
        )
    return {k: data[k] for k in READ_KEYS}


@dataclass
class TargetFrame:
    """One synchronised frame: a record per view (colour and depth resized to the detector's input width, ``boxes``
    the current pseudo-labels in those pixels) and the cameras of the resized views, batch shape ``(V,)``."""

    day: int
    records: list[ImageRecord]
    cameras: Camera


class TargetFrames:
    """The target's frames of ``days`` in file order (the order of the recording within a day), read once.

    ``neighbours(i)`` are the frames just before and after frame ``i`` on the same day; ``background(day, cam)`` is
    that camera's static depth over the day (filled in by ``detector.adapt``).
    """

    def __init__(
        self,
        root: str | Path,
        annotations: dict,
        cfg: DetectorConfig,
        days: list[int] | None = None,
        max_frames: int | None = None,
        progress: bool = True,
    ) -> None:
        cameras = Camera.from_mvor(annotations["cameras_info"])
        entries = []
        for mv in annotations["multiview_images"]:
            images = sorted(mv["images"], key=lambda im: image_camera_index(im, len(cameras)))
            day = image_day(images[0])
            if days is None or day in days:
                entries.append((day, images))
        if not entries:
            held = sorted({image_day(mv["images"][0]) for mv in annotations["multiview_images"]})
            raise ValueError(f"no frames of days {days} in the annotations; they hold days {held}")
        entries = entries[:max_frames] if max_frames else entries
        self.frames: list[TargetFrame] = []
        for day, images in tqdm(entries, desc="read target", unit="frame", disable=not progress):
            records, cams = [], []
            for im in images:
                w, h = int(im["width"]), int(im["height"])
                factor = resize_factor(w, cfg)
                rec = ImageRecord(int(im["id"]), im["file_name"], day, w, h, np.zeros((0, 4), np.float32))
                color, depth = read_record(rec, root, color=True, depth=True)
                color, depth = resize_view(color, depth, factor)
                rec.color, rec.depth = color, depth
                rec.height, rec.width = depth.shape  # the record is now of the resized view
                records.append(rec)
                cams.append(cameras[image_camera_index(im, len(cameras))].scale(factor))
            self.frames.append(TargetFrame(day, records, Camera.stack(cams)))
        self.backgrounds: dict[tuple[int, int], np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def records(self) -> list[ImageRecord]:
        """Every view of every frame, frame by frame."""
        return [r for f in self.frames for r in f.records]

    def neighbours(self, i: int) -> list[int]:
        """The indices of the frames just before and after frame ``i`` on its day."""
        day = self.frames[i].day
        return [j for j in (i - 1, i + 1) if 0 <= j < len(self.frames) and self.frames[j].day == day]

    def depths_of(self, day: int, view: int) -> np.ndarray:
        """``(N, H, W)`` the resized depths of ``view`` over the frames of ``day``."""
        return np.stack([f.records[view].depth for f in self.frames if f.day == day])
