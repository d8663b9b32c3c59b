"""The multi-view sample: what every reader yields and every model consumes.

One :class:`Sample` is one synchronised multi-view frame (MVOR's ``multiview_images`` entry). Coordinates follow
``posenet.cameras``: 3D in mm in the reference (camera 0) frame; 2D in pixels of *this sample's* images (so after
subsampling, boxes and cameras are already scaled). Boxes are ``(x0, y0, x1, y1)`` in the same pixel convention as
the cameras (origin at the centre of the top-left pixel).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posenet.boxes import boxes_of_person
from posenet.cameras import Camera
from posenet.scene import SceneView


@dataclass
class View(SceneView):
    """One camera's image of the frame as a reader yields it: the :class:`posenet.scene.SceneView` (``color``,
    ``depth``, ``camera``, ``height``, ``width``) with its annotations.

    Attributes:
        color: (H, W, 3) uint8 RGB, or None when colour was not loaded.
        depth: (H, W) uint16 depth in mm along z (0 = unknown), or None when depth was not loaded.
        camera: the unbatched :class:`Camera` of this (possibly subsampled) image.
        boxes: (K, 4) float32 person boxes, xyxy pixels.
        box_person_ids: (K,) int64 person id of each box (-1 for boxes without an identity).
        image_id: the dataset's image id of this view.
        file_name: the colour file's path relative to the dataset root.
        cam_index: index of this camera in the dataset's ``cameras_info`` (0 is the reference camera).
    """

    boxes: np.ndarray
    box_person_ids: np.ndarray
    image_id: int
    file_name: str
    cam_index: int
    keypoints2d: np.ndarray | None = None  # (K, J, 3) u, v, visibility flag per box, when annotated


@dataclass
class Sample:
    """One synchronised multi-view frame with its 3D ground truth.

    Attributes:
        id: the multi-view id (MVOR's ``multiview_images[*].id``, e.g. ``"10010000000_10020000000_10030000000"``).
        day: recording day (the unit of the cross-validation folds).
        views: V views, in ``cameras_info`` order.
        poses: (N, J, 3) float32 3D joints in mm, reference frame.
        valid: (N, J) bool, joints annotated (MVOR flag > 0).
        person_ids: (N,) int64 person id of each pose (matches ``View.box_person_ids``).
        support: (N,) int64 number of views in which that person has a box.
        up: (3,) unit vector, the room's up direction (towards the ceiling) in the reference frame, when the
            annotation file knows the room (MVOR's ``firstCamToRoomRef``); else None.
    """

    id: str
    day: int
    views: list[View]
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 10, 3), np.float32))
    valid: np.ndarray = field(default_factory=lambda: np.zeros((0, 10), bool))
    person_ids: np.ndarray = field(default_factory=lambda: np.zeros((0,), np.int64))
    support: np.ndarray = field(default_factory=lambda: np.zeros((0,), np.int64))
    up: np.ndarray | None = None

    @property
    def cameras(self) -> Camera:
        """The V cameras stacked into one camera of batch shape (V,)."""
        return Camera.stack([v.camera for v in self.views])

    def person_boxes(self, person_id: int) -> list[np.ndarray | None]:
        """Per view, the (4,) box of ``person_id``, or None where that person has no box."""
        return boxes_of_person(
            [v.boxes for v in self.views], [v.box_person_ids for v in self.views], person_id
        )
