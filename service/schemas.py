"""Every request and response body of the service, with what each field means and its frame and unit.

Coordinates follow ``posenet.cameras``: 3D points are millimetres in the *reference frame*, the frame that
every view's extrinsics T(view->reference) map into: view 0's camera frame when its extrinsics are the
identity, as with MVOR's calibration (OpenCV axes: x right, y down, z forward). 2D boxes are pixels of the
image as sent, ``(x0, y0, x1, y1)`` with the origin at the centre of the top-left pixel.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from posenet.rig.rigfile import MAX_PIXELS_COORD, CameraIn, Size
from posenet.skeleton import JOINTS

# Fixed-length lists, not tuples: FastAPI writes tuples as OpenAPI 3.0 `items` arrays, which 3.1 rejects.
# Every input number is bounded to what is physically meaningful, so that nothing a client sends can overflow
# the arithmetic downstream (fx = 5e-324 or a translation of 1e308 once gave NaN joints in a 200 response). The
# camera's schema (CameraIn) is posenet.rig.rigfile's: rig.json and the request parse one and the same object.
MAX_PERSON_ID = 2**53 - 1  # the largest integer that every JSON reader (IEEE doubles) holds exactly

PixelCoord = Annotated[float, Field(ge=-MAX_PIXELS_COORD, le=MAX_PIXELS_COORD)]
Box = Annotated[list[PixelCoord], Field(min_length=4, max_length=4)]
Vector3 = Annotated[list[float], Field(min_length=3, max_length=3)]
PersonId = Annotated[int, Field(ge=0, le=MAX_PERSON_ID)]


# ----------------------------------------------------------------------------------------------- request
class ViewIn(BaseModel):
    """One view of the scene. Its images are the form's file parts ``color_<i>`` and ``depth_<i>``."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    camera: CameraIn = Field(..., description="the calibration of this view's camera")
    # 0.01 to 100 mm per unit: the 16-bit range then spans 0.65 m to 6.5 km.
    depth_scale_mm: float = Field(
        1.0,
        ge=0.01,
        le=100.0,
        description="millimetres per depth unit of the 16-bit depth PNG (1.0: the PNG holds mm; "
        "0.1 for 1/10 mm), 0.01 to 100. Depth 0 means unknown.",
    )
    boxes: list[Box] | None = Field(
        None,
        description="reference person boxes in this view, (x0, y0, x1, y1) pixels (a box partly outside the "
        "image is clipped to it for the computation and returned as sent). When any view has boxes, "
        "detection is skipped for every view (reference-box mode; a view with null or [] has no person).",
    )
    person_ids: list[PersonId] | None = Field(
        None,
        description="optional identity of each box (same length as boxes), an integer from 0 to 2^53 - 1: "
        "boxes with the same id in "
        "different views are the same person. Without ids, boxes are grouped across views by the 3D matcher.",
    )


class SceneIn(BaseModel):
    """The ``scene`` form part: one synchronised multi-view frame. View i's images are
    ``color_i``/``depth_i``."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    # minItems documents the rule; the check itself is in service.validation, for a clearer message.
    views: list[ViewIn] = Field(
        ...,
        description="the views (1 to the server's ORPOSE_MAX_VIEWS), in the order of their file parts",
        json_schema_extra={"minItems": 1},
    )
    up: Vector3 | None = Field(
        None,
        description="optional: the room's up direction (towards the ceiling) in the reference frame, any length "
        "(e.g. the z axis of MVOR's firstCamToRoomRef in camera 0's frame). Streams leave persons lying down "
        "(the patient on the table) without a track (ORPOSE_TRACK_MIN_HEIGHT_MM); without it they find the up "
        "from the floor in the depth images (ORPOSE_TRACK_FLOOR_UP). POST /scenes does not use it",
    )


# ----------------------------------------------------------------------------------------------- response
class Joint(BaseModel):
    name: Literal[JOINTS] = Field(..., description="joint name (MVOR order: " + ", ".join(JOINTS) + ")")  # type: ignore[valid-type]
    position: Vector3 = Field(
        ...,
        description="(x, y, z) in mm in the reference frame (the frame the extrinsics map into; "
        "MVOR: camera 0's)",
    )
    confidence: float = Field(
        ...,
        ge=0.0,
        le=1.0,
        description="the calibrated probability that the joint lies within 10 cm of the truth, in [0, 1]: "
        "higher is more certain (fitted on held-out rendered scenes from the spread and the number of "
        "supporting views; see docs/MODEL_CARD.md)",
    )
    spread_mm: float = Field(
        ...,
        ge=0.0,
        description="the network's spread of the joint's 3D estimate, in mm (the softmax-weighted RMS "
        "distance of the contributing lifted pixels from the estimate): smaller is more certain",
    )


class Support(BaseModel):
    view: int = Field(..., ge=0, description="index of a view in which this person has a box")
    box: Box = Field(
        ..., description="the person's box in that view, (x0, y0, x1, y1) pixels of that view's image"
    )
    score: float | None = Field(None, description="detector score in [0, 1]; null for reference boxes")


class Person(BaseModel):
    id: int = Field(
        ...,
        description="the person's id: the client's person_id in reference-box mode with ids, "
        "otherwise an "
        "index 0..P-1 within this response (not tracked across requests)",
    )
    joints: list[Joint] = Field(..., description="the 10 joints, in MVOR order")
    views: list[Support] = Field(..., description="the supporting views (where the person has a box)")


class Timings(BaseModel):
    """Milliseconds spent in each stage of this request on the server."""

    decode: float = Field(
        ..., description="parsing the form, decoding and validating the images and cameras, ms"
    )
    detect: float = Field(..., description="person detection, ms (0 in reference-box mode)")
    match: float = Field(..., description="grouping boxes across views into persons, ms")
    pose: float = Field(..., description="the pose network: heatmaps, lifting and aggregation, ms")
    encode: float = Field(..., description="building and serialising this response, ms")
    total: float = Field(..., description="all of the above plus waiting for a free inference worker, ms")


class SceneOut(BaseModel):
    mode: Literal["reference_boxes", "detector"] = Field(
        ..., description="reference_boxes when the request carried boxes, detector otherwise"
    )
    frame: str = Field(
        "the frame the views' extrinsics T(view->reference) map into (view 0's camera when its T is the "
        "identity, "
        "OpenCV axes x right, y down, z forward); unit mm",
        description="the frame and unit of every 3D coordinate in this response",
    )
    persons: list[Person] = Field(..., description="everyone found in the frame (empty when nobody is)")
    notes: list[str] = Field(
        default_factory=list,
        description="why something is missing or doubtful: a view without valid depth, a person (by id) whose "
        "boxes hold no valid depth and who is therefore left out, or a person seen by one view whose skeleton "
        "has no person's size (its confidence capped)",
    )
    timings: Timings = Field(..., description="server milliseconds per stage of this request")


# ----------------------------------------------------------------------------------------------- streams
class SmoothedJoint(BaseModel):
    name: Literal[JOINTS] = Field(..., description="joint name (MVOR order: " + ", ".join(JOINTS) + ")")  # type: ignore[valid-type]
    position: Vector3 = Field(
        ...,
        description="(x, y, z) in mm in the reference frame, as joints[].position: the tracker's estimate "
        "(smoothed over time, bones held at the track's lengths)",
    )


class TrackedPerson(Person):
    track_id: int | None = Field(
        ...,
        ge=0,
        description="the person's track in this stream: the same number for the same person from frame to "
        "frame (0, 1, ... in order of confirmation). null while the person is not (yet) tracked: seen in "
        "fewer than 3 consecutive frames, a second detection of a tracked person, or too uncertain "
        "(median joint spread above ORPOSE_TRACK_MAX_SPREAD_MM), a torso shorter than any adult's "
        "(ORPOSE_TRACK_MIN_TORSO_MM), or, with ORPOSE_TRACK_STATIC_SCENE, a track parked because its person "
        "showed no sign of life (no move, nothing in front of the room's static depth, no sure upright pose) "
        "for 0.5 s: it gets its number back once they do",
    )
    unsure: bool = Field(
        False,
        description="the detector was unsure of every box of this person (scores below its threshold, from "
        "ORPOSE_CANDIDATE_SCORE up): such a person is answered only when it continues a track (a person half "
        "hidden behind a monitor), never on its own (ORPOSE_TRACK_UNSURE_GATE_MM)",
    )
    smoothed_joints: list[SmoothedJoint] = Field(
        ...,
        description="the 10 joints as the tracker estimates them, in MVOR order (joints holds the raw ones of "
        "this frame). For a person the tracker does not follow (no track and no tentative one) they equal "
        "the raw joints",
    )


class StreamTimings(Timings):
    track: float = Field(..., description="the tracker's update for this frame, ms")
    background: float = Field(
        0.0,
        description="of track: the room's static-depth model (learning it from the frame's depth images and "
        "testing the persons against it; 0 with ORPOSE_TRACK_STATIC_SCENE off), ms",
    )
    unsure: float = Field(
        0.0,
        description="of match: asking the tracker whether a person of boxes the detector was unsure of could "
        "continue one of its tracks, and grouping those boxes into persons when one could (with track, what "
        "tracking adds to a frame), ms",
    )
    floor: float = Field(
        0.0,
        description="looking for the floor in the depth images, for the room's up (a stream's first frame of a "
        "rig, when the scene gives no up; 0 on the others), ms",
    )
    wait: float = Field(
        0.0,
        description="of total: waiting for the stream's turns, behind its earlier frames (the front stage, "
        "decoding and detection, overlaps the pose stage of the frame before), ms",
    )


class StreamState(BaseModel):
    id: str = Field(..., description="the stream's id, as in the path")
    frames: int = Field(
        ...,
        ge=1,
        description="frames this stream has taken, this one included (1: the stream started with this frame)",
    )
    timestamp_s: float = Field(
        ...,
        description="this frame's time, s: the request's timestamp_s, or (on a stream whose first frame had "
        "none) the server's receive time, counted from the stream's first frame",
    )
    clock: Literal["client", "server"] = Field(
        ..., description="client: times are the frames' timestamp_s; server: the server's receive times"
    )
    up: Literal["scene", "floor", "none"] = Field(
        ...,
        description="the room's up direction the tracker used for this frame (persons lying down along it are "
        "not tracked): scene: the scene's up; floor: the floor's normal found in the stream's depth images "
        "(ORPOSE_TRACK_FLOOR_UP); none: neither, so lying persons are tracked too",
    )


class StreamFrameOut(SceneOut):
    status: Literal["answered"] = Field(
        "answered", description="answered: the frame went through the pipeline and the stream's tracker"
    )
    persons: list[TrackedPerson] = Field(  # type: ignore[assignment]
        ..., description="everyone found in the frame (empty when nobody is), with their tracks"
    )
    timings: StreamTimings = Field(..., description="server milliseconds per stage of this request")  # type: ignore[assignment]
    stream: StreamState = Field(..., description="the stream this frame went to")


class StreamFrameDropped(BaseModel):
    """A frame the stream did not take: a newer frame of it arrived while this one waited (service.streams)."""

    status: Literal["dropped"] = Field(
        "dropped",
        description="dropped: frames came faster than the server answers them, and this one was replaced by a "
        "newer frame of its stream before its turn; the stream (its tracks, its last time) is as if it was "
        "never sent",
    )
    stream: str = Field(..., description="the stream's id, as in the path")
    timestamp_s: float = Field(..., description="this frame's time on the stream's clock, s")
    clock: Literal["client", "server"] = Field(..., description="as StreamState.clock")
    newer_timestamp_s: float = Field(..., description="the time of the newer frame that replaced it, s")
    reason: str = Field(..., description="why, in words, and what to do to have every frame answered")
    waited_ms: float = Field(..., description="how long it waited before it was dropped, ms")
    total_ms: float = Field(..., description="from the request's arrival to this answer, ms")


class StreamEnded(BaseModel):
    id: str = Field(..., description="the stream that ended")
    frames: int = Field(..., ge=0, description="frames it had taken")
    tracks: int = Field(..., ge=0, description="tracks it had confirmed (ids 0 to tracks - 1)")


class Runtime(BaseModel):
    network: Literal["pose", "detector"] = Field(..., description="which network")
    backend: str = Field(..., description="torch, onnxruntime or openvino")
    backend_reason: str = Field(
        ..., description="why that backend (ORPOSE_BACKEND, what is installed, a failure)"
    )
    precision: str = Field(..., description="fp32, bf16 or int8")
    precision_reason: str = Field(
        ...,
        description="why that precision (ORPOSE_PRECISION, the CPU's bf16 support; with auto on OpenVINO, whether "
        "int8 was taken: its accuracy cost on record for these weights, and the int8 and float times this "
        "machine measured)",
    )


class ModelInfo(BaseModel):
    joints: list[str] = Field(..., description="the joints every person has, in order")
    modalities: list[str] = Field(
        ..., description="the image modalities the pose network reads (color, depth)"
    )
    detector_modalities: list[str] = Field(
        default_factory=list,
        description="the image modalities the detector reads (empty without a detector): a frame sent without boxes "
        "needs these as well as the pose network's",
    )
    input_size: Size | None = Field(
        None, description="(width, height) the pose network works at, pixels (images are resized to it)"
    )
    read_size: Size | None = Field(
        None,
        description="(width, height) of the views the networks read in full, pixels: a view sent larger is decoded "
        "smaller when it is an exact 2, 4 or 8 times this, so sending it at this size (with its camera's "
        "image_size the calibrated one, an exact 2, 4 or 8 times larger) gives the same answers with a quarter or "
        "less of the bytes and the decoding (service.client --send-size read). Null: views are read as sent",
    )
    pose_trained_on: str = Field(..., description="what the pose network's weights were trained on")
    detector_trained_on: str | None = Field(None, description="what the detector's weights were trained on")
    detector_loaded: bool = Field(..., description="whether detector mode is available")
    device: str = Field(..., description="the torch device the models run on")
    runtime: list[Runtime] = Field(
        default_factory=list, description="how each network runs on this machine: backend, precision and why"
    )
    machine: dict = Field(
        default_factory=dict, description="the machine the service runs on: CPU, cores, capability, versions"
    )


class Health(BaseModel):
    status: Literal["ok"] = Field("ok", description="always ok: the process is alive and answering")


class Ready(BaseModel):
    ready: bool = Field(..., description="true once the models are loaded")


class Error(BaseModel):
    detail: str = Field(..., description="what was wrong with the request and how to fix it")
