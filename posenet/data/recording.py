"""A recording of one's own OR: per-camera colour and depth folders plus a ``rig.json``, and no annotations.

Layout (the MVOR layout without days or annotations)::

    REC/rig.json                      the cameras, in view order (``python -m posenet.rig convert ... --out``)
    REC/<camera>/color/<frame>.png    8-bit colour (any format OpenCV reads)
    REC/<camera>/depth/<frame>.png    16-bit depth in mm along z, 0 = unknown, the same file name as its colour

The camera folders are those holding a ``color`` folder, in natural order (``cam2`` before ``cam10``), unless
``cameras`` names them in rig order; there must be one per ``rig.json`` entry. A frame is a file name present in
every camera's ``color`` *and* ``depth`` folder; frames missing from some camera are left out and counted in
``report``. Samples have no boxes and no poses; their ``file_name`` is relative to ``REC`` with the depth beside it
(``posenet.data.images.depth_file_name``), which is what the batch client sends::

    python -m service.client REC --url http://localhost:8000 --out results.jsonl     # no --annotations
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from posenet.data.images import depth_file_name, read_color, read_depth, subsample_color, subsample_depth
from posenet.data.mvor import MODALITIES, check_reader_options, subsampled_camera
from posenet.data.sample import Sample, View
from posenet.rig.rigfile import read_rig_json
from posenet.skeleton import NUM_JOINTS


def _natural(text: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


class RecordingDataset(torch.utils.data.Dataset):
    """Synchronised frames of a recording folder as :class:`Sample`\\ s without ground truth.

    Args:
        root: the recording folder (see the module docstring).
        rig: the rig file (default ``root / "rig.json"``).
        cameras: the camera folder names in rig order (default: every folder with a ``color`` folder, natural order).
        subsample: integer factor, as in the MVOR reader.
        modalities: which images to load; ``()`` lists frames only (what the batch client needs).
    """

    def __init__(
        self,
        root: str | Path,
        rig: str | Path | None = None,
        cameras: Sequence[str] | None = None,
        subsample: int = 1,
        modalities: Sequence[str] = MODALITIES,
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"recording folder {self.root} is not a folder")
        self.subsample, self.modalities = check_reader_options(subsample, modalities)
        self.rig = read_rig_json(rig or self.root / "rig.json")
        if cameras is None:
            cameras = sorted((p.name for p in self.root.iterdir() if (p / "color").is_dir()), key=_natural)
        self.camera_folders = list(cameras)
        if len(self.camera_folders) != len(self.rig):
            raise ValueError(
                f"{self.root}: {len(self.camera_folders)} camera folders {self.camera_folders} but the rig has "
                f"{len(self.rig)} cameras; name the folders in rig order with cameras=[...]"
            )
        per_camera = []
        for name in self.camera_folders:
            color, depth = self.root / name / "color", self.root / name / "depth"
            if not color.is_dir() or not depth.is_dir():
                raise FileNotFoundError(f"{self.root / name} needs both a color and a depth folder")
            names = {p.name for p in color.iterdir() if p.is_file()}
            per_camera.append(names & {p.name for p in depth.iterdir() if p.is_file()})
        common = set.intersection(*per_camera)
        self.frames = sorted(common, key=_natural)
        union = set.union(*per_camera)
        self.report = [
            f"{self.root.name}: {len(self.frames)} frames in all {len(self.rig)} cameras"
            + (
                f"; {len(union) - len(common)} frames missing from some camera were left out"
                if union - common
                else ""
            )
        ]
        if not self.frames:
            raise ValueError(
                f"{self.root}: no frame has colour and depth in every camera ({self.camera_folders})"
            )

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def ids(self) -> list[str]:
        return [Path(f).stem for f in self.frames]

    @property
    def days(self) -> list[int]:
        return [0]

    def __getitem__(self, index: int) -> Sample:
        frame = self.frames[index]
        views = []
        for v, (folder, camera) in enumerate(zip(self.camera_folders, self.rig.cameras, strict=True)):
            name = f"{folder}/color/{frame}"
            color = depth = None
            if "color" in self.modalities:
                color = subsample_color(read_color(self.root / name, camera.size), self.subsample)
            if "depth" in self.modalities:
                depth = subsample_depth(
                    read_depth(self.root / depth_file_name(name), camera.size), self.subsample
                )
            camera = subsampled_camera(camera, self.subsample)
            views.append(
                View(color, depth, camera, np.zeros((0, 4), np.float32), np.zeros(0, np.int64), image_id=v,
                     file_name=name, cam_index=v, keypoints2d=np.zeros((0, NUM_JOINTS, 3), np.float32))
            )  # fmt: skip
        return Sample(id=self.ids[index], day=0, views=views)
