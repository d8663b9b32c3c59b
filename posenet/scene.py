"""The scene contract: V RGB-D views with their cameras and the persons to estimate as boxes in those views
(:class:`Scene`) go in; one :class:`PersonPose` per person comes out.

Every path to the pose network builds a :class:`Scene`: the dataset readers' samples (:meth:`Scene.from_sample`,
training, validation, offline prediction), the service's requests and the cross-view matchers (their persons'
``posenet.boxes.PersonBoxes``: :meth:`Scene.from_person_boxes`). ``posenet.net.infer.PoseEstimator.predict`` takes it, and
``posenet.net.inputs.build_scene`` turns its views and boxes into the network's inputs.

Pixels and boxes follow ``posenet.boxes`` (xyxy, origin at the centre of the top-left pixel); cameras,
millimetres and frames follow ``posenet.cameras``.

Usage::

    scene = Scene.from_person_boxes(views, person_boxes)   # a posenet.boxes.PersonBoxes; views: V SceneViews
    scene = Scene.from_person_boxes(views, [[box_0, None, box_2], ...])   # or P lists of V boxes or None
    scene = Scene.from_sample(sample, "boxed")                            # a posenet.data.sample.Sample
    scene.boxes      # (P, V, 4) float32 xyxy (zeros where has_box is False)
    scene.has_box    # (P, V) bool
    for pose in estimator.predict(scene).persons():   # PersonPose: joints (J, 3) mm, spread_mm, confidence
        ...
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from posenet.boxes import PersonBoxes, person_ids
from posenet.cameras import Camera
from posenet.skeleton import NUM_JOINTS

Tensor = torch.Tensor


@dataclass
class PersonPose:
    """One person's 3D pose: the one record of an estimate. The pose network's per-person rows
    (``posenet.net.infer.PosePrediction.persons``) are these; the pipeline's persons
    (``pipeline.two_stage.PersonResult``) are these with their boxes and id added; the tracker reads them and the
    service's ``schemas.Person`` is their JSON form.

    Attributes:
        joints: (J, 3) float64 mm, the reference frame (camera 0's).
        spread_mm: (J,) float64 mm, the spread of each joint's lifted heatmap points (smaller is more certain).
        confidence: (J,) float64 in [0, 1], the calibrated probability that each joint lies within 10 cm of the
            truth (``posenet.net.calibration``): the same meaning everywhere.
    """

    joints: np.ndarray
    spread_mm: np.ndarray
    confidence: np.ndarray


@dataclass
class SceneView:
    """One camera's RGB-D image: the one image type. A reader's :class:`posenet.data.sample.View` is one, with
    its annotations added; the service's decoded views and the pipeline's are plain ones.

    Attributes:
        color: (H, W, 3) uint8 RGB, or None (a depth-only network, boxes given without colour, or a reader that
            did not load colour).
        depth: (H, W) uint16 mm along z (0 = unknown); None only in a reader's view loaded without depth (a
            :class:`Scene` needs it: :meth:`Scene.from_sample` says so).
        camera: the unbatched :class:`Camera` of these images.

    ``color, depth, camera = view`` unpacks it, as when it was a tuple.
    """

    color: np.ndarray | None
    depth: np.ndarray | None
    camera: Camera

    def __iter__(self) -> Iterator:
        return iter((self.color, self.depth, self.camera))

    @property
    def height(self) -> int:
        img = self.depth if self.depth is not None else self.color
        return int(img.shape[0]) if img is not None else int(self.camera.size[1])

    @property
    def width(self) -> int:
        img = self.depth if self.depth is not None else self.color
        return int(img.shape[1]) if img is not None else int(self.camera.size[0])


def scene_views(views: Sequence) -> list[SceneView]:
    """``views`` as :class:`SceneView`\\ s: those that are one (a reader's views too) as they are, tuples
    ``(color, depth, camera)`` converted."""
    return [v if isinstance(v, SceneView) else SceneView(*v) for v in views]


@dataclass
class Scene:
    """One synchronised multi-view frame and the P persons to estimate in it.

    Attributes:
        views: V :class:`SceneView`\\ s (a sample's views are; tuples ``(color, depth, camera)`` are converted),
            all of one image size.
        boxes: (P, V, 4) float32 xyxy pixels of each person in each view (ignored where ``has_box`` is False).
            With ``has_box`` and ``person_ids``, the network's tensor form of a ``posenet.boxes.PersonBoxes``
            (:meth:`from_person_boxes`).
        has_box: (P, V) bool, whether the person has a box in that view; the network runs only there.
        person_ids: (P,) int64 identities (the dataset's person ids, the client's, or 0..P-1).
        poses: (P, J, 3) float32 mm, reference frame: the ground truth, zeros where there is none.
        valid: (P, J) bool, the annotated joints of ``poses`` (all False without ground truth).
        id: the frame's id (a sample's multi-view id), or None.
    """

    views: list[SceneView]
    boxes: Tensor
    has_box: Tensor
    person_ids: Tensor
    poses: Tensor | None = None
    valid: Tensor | None = None
    id: str | None = None

    def __post_init__(self) -> None:
        if not self.views:
            raise ValueError("a scene needs at least one view")
        self.views = scene_views(self.views)
        V = len(self.views)
        self.boxes = torch.as_tensor(self.boxes, dtype=torch.float32)
        self.has_box = torch.as_tensor(self.has_box, dtype=torch.bool)
        self.person_ids = torch.as_tensor(self.person_ids, dtype=torch.int64)
        P = self.boxes.shape[0] if self.boxes.ndim else -1
        if self.boxes.shape != (P, V, 4) or self.has_box.shape != (P, V) or self.person_ids.shape != (P,):
            raise ValueError(
                f"a scene of {V} views needs boxes (P, {V}, 4), has_box (P, {V}) and person_ids (P,), got "
                f"{tuple(self.boxes.shape)}, {tuple(self.has_box.shape)}, {tuple(self.person_ids.shape)}"
            )
        if self.poses is None:
            self.poses = torch.zeros(P, NUM_JOINTS, 3)
        self.poses = torch.as_tensor(self.poses, dtype=torch.float32)
        J = self.poses.shape[1] if self.poses.ndim == 3 else -1
        if self.valid is None:
            self.valid = torch.zeros(P, max(J, 0), dtype=torch.bool)
        self.valid = torch.as_tensor(self.valid, dtype=torch.bool)
        if self.poses.shape != (P, J, 3) or self.valid.shape != (P, J):
            raise ValueError(
                f"a scene of {P} persons needs poses (P, J, 3) and valid (P, J), got {tuple(self.poses.shape)} "
                f"and {tuple(self.valid.shape)}"
            )

    @property
    def num_persons(self) -> int:
        return self.boxes.shape[0]

    @property
    def support(self) -> Tensor:
        """(P,) int64: the number of views in which each person has a box."""
        return self.has_box.sum(1)

    @classmethod
    def from_person_boxes(
        cls,
        views: Sequence[SceneView],
        persons: PersonBoxes | Sequence[Sequence],
        person_ids: Sequence[int] | None = None,
        id: str | None = None,
    ) -> Scene:
        """The scene of the persons ``persons``: a :class:`posenet.boxes.PersonBoxes` (the pipeline's), or P
        lists of V entries, each an xyxy box (pixels of that view) or None (a client's, a test's), whose ids are
        ``person_ids`` (default 0..P-1).

        Raises ValueError naming the person and view of an entry that is not one box per view, finite, with
        x1 > x0 and y1 > y0.
        """
        if not isinstance(persons, PersonBoxes):
            persons = PersonBoxes.from_lists(persons, len(views), person_ids, check=True)
        elif persons.num_views != len(views):
            raise ValueError(f"the persons' boxes are in {persons.num_views} views, the scene has {len(views)}")
        else:
            persons.validate()
        return cls(
            list(views),
            torch.from_numpy(persons.boxes.astype(np.float32)),
            torch.from_numpy(persons.has_box),
            torch.from_numpy(persons.ids),
            id=id,
        )

    @classmethod
    def from_sample(cls, sample, which: str = "annotated") -> Scene:
        """The persons of a :class:`posenet.data.sample.Sample` with a box in some view, and their truth.

        ``which``: ``"annotated"``, its 3D poses (training, validation); ``"boxed"``, every person of
        ``posenet.boxes.person_ids`` (prediction), with zeros and False for those without a 3D pose.
        """
        if any(v.depth is None for v in sample.views):
            raise ValueError(
                f"sample {sample.id}: every view needs a depth image (load the dataset with depth)"
            )
        J = sample.poses.shape[1] if sample.poses.ndim == 3 else NUM_JOINTS
        if which == "annotated":
            ids = [int(i) for i in sample.person_ids]
            poses, valid = sample.poses, sample.valid
        elif which == "boxed":
            ids = person_ids([v.box_person_ids for v in sample.views])
            index = {int(pid): k for k, pid in enumerate(sample.person_ids)}
            # Persons without a 3D pose (or frames with no identified person at all) get zeros and False.
            poses, valid = np.zeros((len(ids), J, 3), np.float32), np.zeros((len(ids), J), bool)
            for p, i in enumerate(ids):
                if i in index:
                    poses[p], valid[p] = sample.poses[index[i]], sample.valid[index[i]]
        else:
            raise ValueError(f"which must be 'annotated' or 'boxed', got {which!r}")
        persons = PersonBoxes.from_lists([sample.person_boxes(pid) for pid in ids], len(sample.views), ids)
        keep = persons.has_box.any(1)
        return cls(
            list(sample.views),
            torch.from_numpy(persons.boxes[keep].astype(np.float32)),
            torch.from_numpy(persons.has_box[keep]),
            torch.from_numpy(persons.ids[keep]),
            torch.from_numpy(np.asarray(poses, np.float32)[keep]),
            torch.from_numpy(np.asarray(valid, bool)[keep]),
            sample.id,
        )
