"""Per-view detection data: the boxes of an MVOR-format annotation file, one training image per camera view.

The detector trains and is evaluated per image (DETR's and COCO's unit), so this reads the COCO part of an
MVOR-format file (``images`` + ``annotations``) rather than ``posenet.data.mvor``'s multi-view samples, which
would decode all V views of a frame to use one. Boxes follow ``posenet.boxes``: xyxy pixels of the full-size
image. Days come from ``posenet.data.mvor.image_day``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from detector.augment import AugmentConfig, augment_view
from detector.inputs import batch_inputs, box_frame, normalise, resize_factor, resize_view
from detector.model import DetectorConfig
from posenet.boxes import coco_to_xyxy, scale_xyxy, xyxy_to_cxcywh_norm
from posenet.data.images import depth_file_name, read_color, read_depth
from posenet.data.mvor import image_day, read_annotation_json


@dataclass
class ImageRecord:
    """One camera view and its person boxes.

    Attributes:
        image_id: the annotation file's image id.
        file_name: colour file relative to the dataset root (depth lies beside it under ``depth/``).
        day: recording day (the cross-validation unit).
        width, height: full image size in pixels.
        boxes: (K, 4) float32 xyxy pixels of the full-size image.
        color, depth: the images themselves, when held in memory instead of read from ``root``.
        root: the dataset root of this record, when it differs from the one its reader was given (training
            on several datasets at once, ``--extra-data``).
    """

    image_id: int
    file_name: str
    day: int
    width: int
    height: int
    boxes: np.ndarray
    color: np.ndarray | None = None
    depth: np.ndarray | None = None
    root: str | None = None


def load_records(annotations: str | Path | dict, days: list[int] | None = None) -> list[ImageRecord]:
    """One :class:`ImageRecord` per image of ``days`` (all days when None), sorted by image id."""
    data = annotations if isinstance(annotations, dict) else read_annotation_json(annotations)
    source = "the annotation dict" if isinstance(annotations, dict) else f"annotation file {annotations}"
    for key in ("images", "annotations"):
        if key not in data:
            raise ValueError(f"{source} has no {key!r} list: not an MVOR/COCO-format file")
    boxes: dict[int, list] = {}
    for ann in data["annotations"]:
        boxes.setdefault(int(ann["image_id"]), []).append(ann["bbox"])
    records = []
    for image in data["images"]:
        day = image_day(image)
        if days is not None and day not in days:
            continue
        b = np.asarray(boxes.get(int(image["id"]), []), np.float32).reshape(-1, 4)
        records.append(
            ImageRecord(
                int(image["id"]),
                image["file_name"],
                day,
                int(image["width"]),
                int(image["height"]),
                coco_to_xyxy(b),
            )
        )
    if days is not None and not records:
        raise ValueError(f"no images of days {days} in the annotations")
    return sorted(records, key=lambda r: r.image_id)


def read_record(
    record: ImageRecord, root: str | Path | None, color: bool, depth: bool
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The full-size colour ``(H, W, 3)`` uint8 RGB and/or depth ``(H, W)`` uint16 of a record."""
    size = (record.width, record.height)
    root = record.root if record.root is not None else root
    c = d = None
    if color:
        c = record.color if record.color is not None else read_color(Path(root) / record.file_name, size)
    if depth:
        d = record.depth
        if d is None:
            d = read_depth(Path(root) / depth_file_name(record.file_name), size)
    return c, d


class DetectionDataset(Dataset):
    """Views as DETR training examples.

    With ``cache``, resized views are kept in memory after their first read (one process: ``num_workers``
    0). Item: ``(pixel_values (C, H, W), labels, image_id)``; ``labels`` is DETR's dict of ``class_labels (K,)``
    (all 0, "person") and ``boxes (K, 4)`` normalised (cx, cy, w, h) of the item's own size (``inputs.box_frame``).
    """

    def __init__(
        self,
        records: list[ImageRecord],
        root: str | Path | None,
        cfg: DetectorConfig,
        augment: AugmentConfig | None = None,
        seed: int = 0,
        cache: bool = False,
    ) -> None:
        self.records, self.root, self.cfg, self.augment = records, root, cfg, augment
        self.rng = np.random.default_rng(seed)
        self.cache = cache
        self._cache: dict[int, tuple] = {}

    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, dict, int]:
        rec = self.records[index]
        if index in self._cache:
            color, depth, boxes = self._cache[index]
        else:
            use_color = self.cfg.input_mode in ("rgb", "rgbd")
            use_depth = self.cfg.input_mode in ("depth", "rgbd")
            color, depth = read_record(rec, self.root, use_color, use_depth)
            factor = resize_factor(rec.width, self.cfg)
            color, depth = resize_view(color, depth, factor)
            boxes = scale_xyxy(rec.boxes, factor)
            if self.cache:  # the resized view, before augmentation (a 160x120 RGB view is 58 kB)
                self._cache[index] = (color, depth, boxes)
        if self.augment is not None:
            color, depth, boxes = augment_view(color, depth, boxes, self.augment, self.rng)
        x = normalise(color, depth, self.cfg)  # (C, H, W)
        w, h = box_frame(x.shape[2], x.shape[1], self.cfg)
        target = torch.from_numpy(xyxy_to_cxcywh_norm(np.asarray(boxes, np.float32), w, h)).float()
        labels = {"class_labels": torch.zeros(len(target), dtype=torch.long), "boxes": target.reshape(-1, 4)}
        return x, labels, rec.image_id


def collate(batch: list, multiple: int = 1) -> dict:
    """Items to ``{"pixel_values", "pixel_mask", "labels", "image_ids"}`` (padded to ``multiple``, see
    ``inputs.batch_inputs``)."""
    pixels, mask = batch_inputs([b[0] for b in batch], multiple)
    return {
        "pixel_values": pixels,
        "pixel_mask": mask,
        "labels": [b[1] for b in batch],
        "image_ids": [b[2] for b in batch],
    }


def worker_init(worker_id: int) -> None:
    """Give each DataLoader worker its own augmentation stream (forked workers would share the parent's)."""
    info = torch.utils.data.get_worker_info()
    info.dataset.rng = np.random.default_rng(info.seed % (2**32))
