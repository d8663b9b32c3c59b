"""A camera rig and its ``rig.json``: the per-view ``camera`` objects that ``POST /scenes`` takes.

``rig.json`` is a JSON list with one object per camera, in view order, each with exactly the fields of
:class:`CameraIn`, the camera schema that ``POST /scenes`` validates too::

    [{"fx": 538.6, "fy": 538.2, "cx": 315.8, "cy": 241.9, "distortion": null,
      "extrinsics": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "image_size": [640, 480]}, ...]

so a converted rig can be pasted into a request as it is. Every convention is ``posenet.cameras``'s: mm, OpenCV
axes, ``extrinsics`` = T(v->ref) mapping camera-v points into the reference frame, distortion in OpenCV's order
(k1, k2, p1, p2, k3). The reference frame is the first camera's (its extrinsics are the identity) unless the
rig was converted with ``--ref world``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import pydantic
import torch
from pydantic import BaseModel, ConfigDict, Field

from posenet.cameras import Camera, is_rigid, rigid_inverse

# Every number is bounded to what is physically meaningful, so that nothing a client sends can overflow the
# arithmetic downstream. Fixed-length lists, not tuples: FastAPI writes tuples as OpenAPI 3.0 `items` arrays.
MAX_PIXELS_COORD = 1e5  # pixel coordinates and focal lengths: no camera has 100 000 pixels across
MAX_TRANSLATION_MM = 1e5  # 100 m: far beyond any operating room
MAX_DISTORTION = 100.0  # |OpenCV coefficient|; real calibrations stay within about 20 (MVOR's largest: 13.3)
Size = Annotated[list[Annotated[int, Field(ge=1, le=65535)]], Field(min_length=2, max_length=2)]
Distortion = Annotated[
    list[Annotated[float, Field(ge=-MAX_DISTORTION, le=MAX_DISTORTION)]], Field(min_length=5, max_length=5)
]
# Rotation entries lie in [-1, 1] (the rigidity check), translations within MAX_TRANSLATION_MM.
MatrixEntry = Annotated[float, Field(ge=-MAX_TRANSLATION_MM, le=MAX_TRANSLATION_MM)]
Matrix4 = Annotated[
    list[Annotated[list[MatrixEntry], Field(min_length=4, max_length=4)]], Field(min_length=4, max_length=4)
]


class CameraIn(BaseModel):
    """One view's calibration (MVOR's ``cameras_info.camParams`` for that camera, in these names)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    fx: float = Field(
        ..., ge=1, le=MAX_PIXELS_COORD, description="focal length along x, pixels (MVOR: focallength[0])"
    )
    fy: float = Field(
        ..., ge=1, le=MAX_PIXELS_COORD, description="focal length along y, pixels (MVOR: focallength[1])"
    )
    cx: float = Field(
        ...,
        ge=0,
        le=MAX_PIXELS_COORD,
        description="principal point x, pixels (MVOR: principalpoint[0]); inside the image",
    )
    cy: float = Field(
        ...,
        ge=0,
        le=MAX_PIXELS_COORD,
        description="principal point y, pixels (MVOR: principalpoint[1]); inside the image",
    )
    distortion: Distortion | None = Field(
        None,
        description="OpenCV order (k1, k2, p1, p2, k3), each within +-100, or null for an ideal pinhole. "
        "MVOR stores "
        "(k1, k2, k3, p1, p2) and its own 3D annotations ignore distortion: send null for MVOR.",
    )
    extrinsics: Matrix4 = Field(
        ...,
        description="4x4 rigid transform T(view->reference), row-major, translation in mm: p_ref = R "
        "p_view + t, each entry within +-1e5 (translations up to 100 m). "
        "The reference frame is the one these transforms map into; with MVOR's calibration "
        "(cameras_info.camParams.extrinsics[v] reshaped to 4x4) it is camera 0's, whose T is the identity.",
    )
    image_size: Size | None = Field(
        None,
        description="(width, height) in pixels the intrinsics were calibrated for; if given, the "
        "images sent must have exactly this size (MVOR: imagesize), or exactly 1/2, 1/4 or 1/8 of it: such images "
        "are read as the calibrated image reduced (GET /model's read_size is the smallest the networks read in "
        "full), and every coordinate (boxes sent and answered) stays in the calibrated pixels",
    )


CAMERA_FIELDS = tuple(CameraIn.model_fields)


@dataclass
class Rig:
    """V unbatched cameras that share one reference frame, with what was learnt while reading them.

    Attributes:
        cameras: V :class:`Camera` objects (float64), extrinsics T(v->ref) in mm.
        names: V camera names (file names, serial numbers, EasyMocap keys); used by the exporters.
        frame: what the reference frame is, in words (``"camera 0"``, ``"world (EasyMocap)"``).
        report: the conventions and units found or assumed while reading, one line each, for the user.
        to_room: optional (4, 4) T(ref->room), mm, e.g. from MVOR's ``firstCamToRoomRef``: a frame with a known
            floor, used by ``--ref world`` and by the check picture.
    """

    cameras: list[Camera]
    names: list[str]
    frame: str = "camera 0"
    report: list[str] = field(default_factory=list)
    to_room: torch.Tensor | None = None

    def __post_init__(self) -> None:
        if len(self.cameras) != len(self.names):
            raise ValueError(f"{len(self.cameras)} cameras but {len(self.names)} names")
        if not self.cameras:
            raise ValueError("a rig needs at least one camera")

    def __len__(self) -> int:
        return len(self.cameras)

    @property
    def stacked(self) -> Camera:
        """The cameras as one camera of batch shape (V,)."""
        return Camera.stack(self.cameras)

    @property
    def first_is_reference(self) -> bool:
        """Whether the reference frame is camera 0's (its extrinsics are the identity, to 1e-9)."""
        T = self.cameras[0].extrinsics
        return bool((T - torch.eye(4, dtype=T.dtype)).abs().max() < 1e-9)

    def reframed(self, ref_from_old: torch.Tensor, frame: str) -> Rig:
        """The same rig in another frame: ``ref_from_old`` (4, 4) maps old reference points to the new frame."""
        cams = [Camera(c.intrinsics, ref_from_old @ c.extrinsics, c.distortion, c.size) for c in self.cameras]
        to_room = None if self.to_room is None else self.to_room @ rigid_inverse(ref_from_old)
        return Rig(cams, list(self.names), frame, list(self.report), to_room)

    def to_first_camera(self) -> Rig:
        """The rig with camera 0's frame as reference (MVOR's convention): T'(v->0) = T(0->ref)^-1 T(v->ref)."""
        if self.first_is_reference:
            return self
        return self.reframed(rigid_inverse(self.cameras[0].extrinsics), "camera 0")

    def to_room_frame(self) -> Rig:
        """The rig in its room frame (``to_room``); ValueError when the input had none."""
        if self.to_room is None:
            raise ValueError(f"this rig's input has no room/world frame besides its reference ({self.frame})")
        rig = self.reframed(self.to_room, "room")
        rig.to_room = torch.eye(4, dtype=torch.float64)
        return rig


# ----------------------------------------------------------------------------------------------- rig.json
def camera_json(camera: Camera) -> dict:
    """One camera as the service's ``camera`` object (``CameraIn``'s fields, plain floats)."""
    fx, fy, cx, cy = (float(x) for x in camera.intrinsics)
    return {
        "fx": fx,
        "fy": fy,
        "cx": cx,
        "cy": cy,
        "distortion": None if camera.distortion is None else [float(x) for x in camera.distortion],
        "extrinsics": [[float(x) for x in row] for row in camera.extrinsics],
        "image_size": None if camera.size is None else [int(camera.size[0]), int(camera.size[1])],
    }


def camera_from_json(entry: dict, where: str = "camera") -> Camera:
    """A camera from one ``rig.json`` / request ``camera`` object (:class:`CameraIn`); ValueError naming
    ``where`` and each problem."""
    try:
        cam = CameraIn.model_validate(entry)
    except pydantic.ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join([where, *(str(p) for p in e['loc'])])}: {e['msg']}" for e in exc.errors()[:5]
        )
        raise ValueError(f"{problems} (fields: {list(CAMERA_FIELDS)})") from None
    return camera_of(cam)


def camera_of(cam: CameraIn, size: tuple[int, int] | None = None) -> Camera:
    """The :class:`Camera` of a validated camera object; ``size`` (W, H) stands in for its ``image_size``."""
    if size is None and cam.image_size is not None:
        size = (int(cam.image_size[0]), int(cam.image_size[1]))
    T = torch.tensor(cam.extrinsics, dtype=torch.float64)
    return Camera.create(cam.fx, cam.fy, cam.cx, cam.cy, T, cam.distortion, size)


def write_rig_json(rig: Rig, path: str | Path) -> None:
    """Write ``rig.json`` (see the module docstring)."""
    Path(path).write_text(json.dumps([camera_json(c) for c in rig.cameras], indent=1) + "\n")


def read_rig_json(path: str | Path, names: Sequence[str] | None = None) -> Rig:
    """Read a ``rig.json``; its frame is camera 0's when the first extrinsics are the identity."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"rig file {path} does not exist")
    entries = json.loads(path.read_text())
    if isinstance(entries, dict) and "views" in entries:  # a whole scene request: take its cameras
        entries = [v["camera"] for v in entries["views"]]
    if not isinstance(entries, list) or not entries:
        raise ValueError(f"{path}: expected a non-empty JSON list of camera objects")
    cameras = [camera_from_json(e, f"{path.name}[{i}]") for i, e in enumerate(entries)]
    bad = [i for i, c in enumerate(cameras) if not bool(is_rigid(c.extrinsics))]
    if bad:
        raise ValueError(
            f"{path}: the extrinsics of cameras {bad} are not rigid transforms (rotation + mm translation)"
        )
    rig = Rig(cameras, list(names) if names else [f"cam{i}" for i in range(len(cameras))])
    rig.frame = "camera 0" if rig.first_is_reference else "the rig file's reference frame"
    rig.report.append(f"{path.name}: {len(cameras)} cameras, T(v->ref) in mm, reference frame: {rig.frame}")
    return rig


def rig_difference(a: Rig, b: Rig) -> float:
    """The largest relative difference between two rigs' cameras (intrinsics, extrinsics, distortion, size).

    Intrinsics and distortion are compared relative to their own norms; translations relative to the rig's
    size (the largest camera distance from the reference), rotations absolutely (they are of norm 1).
    """
    if len(a) != len(b):
        return float("inf")
    scale = max(float(c.position.norm()) for c in b.cameras) or 1.0
    worst = 0.0
    for ca, cb in zip(a.cameras, b.cameras, strict=True):
        if ca.size != cb.size or (ca.distortion is None) != (cb.distortion is None):
            return float("inf")
        worst = max(worst, float((ca.intrinsics - cb.intrinsics).norm() / cb.intrinsics.norm()))
        worst = max(worst, float((ca.extrinsics[:3, :3] - cb.extrinsics[:3, :3]).abs().max()))
        worst = max(worst, float((ca.extrinsics[:3, 3] - cb.extrinsics[:3, 3]).norm()) / scale)
        if ca.distortion is not None:
            worst = max(
                worst, float((ca.distortion - cb.distortion).norm() / cb.distortion.norm().clamp_min(1e-12))
            )
    return worst
