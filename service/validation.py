"""From the request's parts to checked pipeline inputs: the scene JSON, the cameras, the images and the boxes.

Everything a client can get wrong is checked here, and each problem raises :class:`~service.errors.InputError`
naming the part (``scene``, ``views[1].camera``, ``depth_2``) and what to do about it. HTTP itself (multipart
parsing, body limits) stays in ``service/routes.py``; the pipeline receives only validated numpy arrays.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import pydantic

from posenet.cameras import Camera, is_rigid, rescale_pixels
from posenet.net.inputs import reduction
from posenet.rig.check import scene_findings
from posenet.rig.rigfile import camera_of
from posenet.scene import SceneView
from service.decode import decode_color, decode_depth, header_size
from service.errors import InputError
from service.schemas import SceneIn, ViewIn


@dataclass(frozen=True)
class Limits:
    """The request limits that validation enforces (a subset of :class:`service.settings.Settings`)."""

    max_views: int = 8
    max_image_pixels: int = 1920 * 1200
    max_boxes_per_view: int = 64
    # (W, H) that the models read (ScenePipeline.read_size): views that are an exact multiple of it are decoded
    # at that resolution (posenet.net.inputs.reduction); None keeps every view as sent.
    read_size: tuple[int, int] | None = None


@dataclass
class ValidatedScene:
    """A request ready for :meth:`pipeline.two_stage.ScenePipeline.run`.

    Attributes:
        views: V :class:`posenet.scene.SceneView`\\ s (colour (H, W, 3) uint8 RGB or None, depth (H, W) uint16 mm,
            Camera).
        boxes: per view (K_v, 4) float32 xyxy reference boxes, or None for detector mode.
        person_ids: per view (K_v,) int64 client identities of the boxes, or None (match across views).
        sent_boxes: per view (K_v, 4) float64 boxes as the client sent them (``boxes`` is clipped to the
            image), or None: the response reports these.
        reduced: per view the factor k from the pixels of the request's coordinates (the images as sent, or the
            calibrated ones of the camera's ``image_size`` when the images were sent 1/2, 1/4 or 1/8 of it) to
            those decoded (1: the same). ``views`` and ``boxes`` are in the decoded pixels (u' = (u + 0.5) / k -
            0.5, as ``Camera.scale``).
        up: (3,) unit vector, the room's up direction in the reference frame, or None (not sent).
        notes: named findings about the views that go with the answer (``posenet.rig.check.scene_findings``:
            ``views_disagree``); those that make any answer wrong are refused with a 422 instead.
    """

    views: list[SceneView]
    boxes: list[np.ndarray] | None
    person_ids: list[np.ndarray] | None
    sent_boxes: list[np.ndarray] | None = None
    reduced: list[int] | None = None
    up: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)


def _problem(err: dict) -> str:
    """One of pydantic's errors in the client's terms (``views.0.camera.extrinsics: ...``)."""
    loc = [str(p) for p in err["loc"]]
    where = ".".join(loc) or "scene"
    if "extrinsics" in loc and err["type"] in ("too_short", "too_long"):
        return (
            f"{where}: {err['msg']}; extrinsics is the 4x4 matrix T(view->reference) as 4 rows of 4 numbers "
            "(a 3x4 [R | t] needs the row [0, 0, 0, 1] appended)"
        )
    return f"{where}: {err['msg']}"


def parse_scene(text: str | bytes, limits: Limits) -> SceneIn:
    """The ``scene`` part's JSON, validated against :class:`SceneIn`."""
    try:
        scene = SceneIn.model_validate_json(text)
    except pydantic.ValidationError as exc:
        problems = "; ".join(_problem(err) for err in exc.errors()[:5])
        raise InputError(f"scene JSON is invalid: {problems}") from None
    if not scene.views:
        raise InputError("scene has 0 views; send at least one view (camera + depth_0 image)")
    if len(scene.views) > limits.max_views:
        raise InputError(f"scene has {len(scene.views)} views, more than the limit of {limits.max_views}")
    return scene


def _camera(view: ViewIn, i: int, width: int, height: int) -> Camera:
    cam = view.camera
    where = f"views[{i}].camera"
    if cam.image_size is not None and tuple(cam.image_size) != (width, height):
        raise InputError(
            f"{where}.image_size is {cam.image_size[0]}x{cam.image_size[1]} but view {i}'s images are "
            f"{width}x{height}; send the images at the calibrated size (or exactly 1/2, 1/4 or 1/8 of it) or "
            "rescale the intrinsics"
        )
    if not (0 <= cam.cx <= width and 0 <= cam.cy <= height):
        raise InputError(
            f"{where}: the principal point ({cam.cx:.1f}, {cam.cy:.1f}) lies outside view {i}'s "
            f"{width}x{height} "
            "image; the intrinsics were probably calibrated for another resolution"
            + (
                ""
                if cam.image_size is not None
                else " (images sent at 1/2, 1/4 or 1/8 of the calibrated size need the camera's image_size)"
            )
        )
    camera = camera_of(cam, size=(width, height))
    if not bool(is_rigid(camera.extrinsics)):
        raise InputError(
            f"{where}.extrinsics is not a rigid transform (the rotation must be orthonormal with "
            f"determinant +1 "
            "and the last row (0, 0, 0, 1)); send T(view->reference) with translation in mm"
        )
    return camera


def _boxes(
    view: ViewIn, i: int, width: int, height: int, limits: Limits
) -> tuple[np.ndarray, np.ndarray | None]:
    """The view's boxes clipped to its image (K, 4) float32, and its person ids (K,) int64 or None."""
    boxes = np.asarray(view.boxes or [], dtype=np.float64).reshape(-1, 4)  # (K, 4)
    if len(boxes) > limits.max_boxes_per_view:
        raise InputError(f"views[{i}].boxes has {len(boxes)} boxes, more than {limits.max_boxes_per_view}")
    bad = (boxes[:, 2] <= boxes[:, 0]) | (boxes[:, 3] <= boxes[:, 1])
    outside = (boxes[:, 2] < 0) | (boxes[:, 3] < 0) | (boxes[:, 0] > width - 1) | (boxes[:, 1] > height - 1)
    if bad.any():
        raise InputError(
            f"views[{i}].boxes[{int(np.argmax(bad))}] is empty: boxes are (x0, y0, x1, y1), x1 > x0, y1 > y0"
        )
    if outside.any():
        raise InputError(
            f"views[{i}].boxes[{int(np.argmax(outside))}] lies outside the {width}x{height} image"
        )
    boxes = np.clip(boxes, 0, [width - 1, height - 1, width - 1, height - 1]).astype(np.float32)
    if view.person_ids is None:
        return boxes, None
    ids = np.asarray(view.person_ids, dtype=np.int64)
    if len(ids) != len(boxes):
        raise InputError(f"views[{i}].person_ids has {len(ids)} entries for {len(boxes)} boxes")
    if len(np.unique(ids)) != len(ids):
        raise InputError(f"views[{i}].person_ids repeats an id: one person has at most one box per view")
    return boxes, ids


# OpenCV's decoders release the GIL: the images of a frame decode in parallel (3 views: ~2x faster on 2 cores).
# One thread per core, at most 4: on 2 cores 4 threads were slower than 2 (6.9 against 6.3 ms a frame, 2026-11-30).
_DECODERS = ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 2), thread_name_prefix="decode")


def _decode_all(
    scene: SceneIn, files: Mapping[str, bytes], limits: Limits, factors: list[int]
) -> dict[str, Future]:
    """Start decoding every view's colour and depth part; ``result()`` returns the image or raises its
    InputError."""
    jobs = {}
    for i, view in enumerate(scene.views):
        k = factors[i]  # decoded 1/k of the size sent
        if f"depth_{i}" in files:
            jobs[f"depth_{i}"] = _DECODERS.submit(
                decode_depth,
                files[f"depth_{i}"],
                f"depth_{i}",
                view.depth_scale_mm,
                limits.max_image_pixels,
                k,
            )
        if f"color_{i}" in files:
            jobs[f"color_{i}"] = _DECODERS.submit(
                decode_color, files[f"color_{i}"], f"color_{i}", limits.max_image_pixels, k
            )
    return jobs


SENT_REDUCTIONS = (2, 4, 8)  # an image this many times smaller than its camera's image_size: sent reduced


def _reduction(scene: SceneIn, files: Mapping[str, bytes], i: int, limits: Limits) -> tuple[int, int]:
    """View i's factors ``(sent, decode)``: ``sent`` k when its images are exactly 1/k of its camera's
    ``image_size`` (the client reduced them: they are read as the calibrated image brought to 1/k, and every
    coordinate stays in the calibrated pixels), and the factor they are decoded smaller by, from the depth
    header. Both are 1 unless the colour has the depth's size, so that a size mismatch is reported in the pixels
    that were sent."""
    sizes = []
    for part in (f"depth_{i}", f"color_{i}"):
        if part in files:
            try:
                sizes.append(header_size(files[part], part))
            except InputError:
                return 1, 1  # the decoder reports it
    if not sizes or len(set(sizes)) != 1:
        return 1, 1
    (width, height), calibrated = sizes[0], scene.views[i].camera.image_size
    sent = next(
        (
            k
            for k in SENT_REDUCTIONS
            if calibrated is not None and [width * k, height * k] == list(calibrated)
        ),
        1,
    )
    return sent, reduction(width, height, limits.read_size)


def validate_scene(
    scene: SceneIn, files: Mapping[str, bytes], limits: Limits, need_color: bool, detector_color: bool = True
) -> ValidatedScene:
    """Decode and check every view of ``scene`` with its file parts ``color_<i>`` / ``depth_<i>``.

    ``need_color``: whether colour images are required (the pose network reads colour). ``detector_color``:
    whether a frame without boxes (detector mode) needs them too (the detector reads colour).
    """
    expected = {f"{kind}_{i}" for i in range(len(scene.views)) for kind in ("color", "depth")}
    unexpected = sorted(set(files) - expected)
    if unexpected:
        raise InputError(
            f"unexpected file part(s) {', '.join(unexpected)}: a scene of {len(scene.views)} views takes "
            f"color_0..color_{len(scene.views) - 1} and depth_0..depth_{len(scene.views) - 1}"
        )
    reference_mode = any(v.boxes is not None for v in scene.views)
    with_ids = [v.person_ids is not None for v in scene.views if v.boxes]
    if any(with_ids) and not all(with_ids):
        raise InputError(
            "person_ids are given in some views with boxes but not in others: give them for all or none"
        )
    if not reference_mode and any(v.person_ids is not None for v in scene.views):
        raise InputError("person_ids were given without boxes")
    # why a view without colour is refused (None: colour is optional)
    color_reason = (
        "the pose network reads colour"
        if need_color
        else "detection needs colour"
        if not reference_mode and detector_color
        else None
    )
    factors = [_reduction(scene, files, i, limits) for i in range(len(scene.views))]
    decoded = _decode_all(scene, files, limits, [decode for _, decode in factors])
    reduced = [sent * decode for sent, decode in factors]  # from the calibrated pixels to those decoded
    try:
        return _validated(scene, files, limits, color_reason, reference_mode, decoded, reduced)
    finally:
        for job in decoded.values():
            job.cancel()  # after an error: drop what has not started


def _validated(
    scene: SceneIn,
    files: Mapping[str, bytes],
    limits: Limits,
    color_reason: str | None,
    reference_mode: bool,
    decoded: dict[str, Future],
    reduced: list[int],
) -> ValidatedScene:
    """The views in order, with the first error of the first view that has one (as a sequential check)."""
    views, all_boxes, all_ids = [], [], []
    for i, view in enumerate(scene.views):
        if f"depth_{i}" not in files:
            raise InputError(f"missing file part depth_{i}: every view needs a 16-bit depth PNG")
        depth = decoded[f"depth_{i}"].result()
        k = reduced[i]
        # the request's pixels (as sent, or the calibrated ones): every check and message uses these
        height, width = depth.shape[0] * k, depth.shape[1] * k
        color = None
        if f"color_{i}" in files:
            color = decoded[f"color_{i}"].result()
            if color.shape[:2] != depth.shape:
                raise InputError(
                    f"color_{i} is {color.shape[1] * k}x{color.shape[0] * k} but depth_{i} is {width}x{height}: "
                    "the colour and depth of a view must be registered at the same size"
                )
        elif color_reason is not None:
            raise InputError(f"missing file part color_{i} ({color_reason}); send a PNG or JPEG colour image")
        camera = _camera(view, i, width, height)
        views.append(SceneView(color, depth, camera if k == 1 else camera.scale(1 / k)))
        boxes, ids = _boxes(view, i, width, height, limits)
        all_boxes.append(boxes if k == 1 else rescale_pixels(boxes, 1 / k).astype(np.float32))
        all_ids.append(ids)
    if not any(v.depth.any() for v in views):
        raise InputError(
            "every depth image holds only 0 (unknown), so no person can be lifted to 3D: send the sensor's "
            "16-bit depth in mm (check that the depth files are not blank and depth_scale_mm is right)"
        )
    up = _up(scene.up)
    findings = scene_findings([v.camera for v in views], [v.depth for v in views])
    for f in findings:
        if f.error:
            raise InputError(f"{f.name}: {f.message}")
    notes = [f"{f.name}: {f.message}" for f in findings]
    if not reference_mode:
        return ValidatedScene(views, None, None, reduced=reduced, up=up, notes=notes)
    has_ids = any(ids is not None for ids in all_ids)
    ids = [np.zeros(0, np.int64) if x is None else x for x in all_ids] if has_ids else None
    sent = [np.asarray(v.boxes or [], dtype=np.float64).reshape(-1, 4) for v in scene.views]
    return ValidatedScene(views, all_boxes, ids, sent, reduced, up, notes)


def _up(up: list[float] | None) -> np.ndarray | None:
    """The scene's ``up`` as a unit vector; 422 when it has no direction."""
    if up is None:
        return None
    v = np.asarray(up, np.float64)  # finite: SceneIn refuses inf and NaN
    scale = float(np.abs(v).max())
    if not scale > 0:
        raise InputError(
            f"up {up} has no direction: give the room's up direction (towards the ceiling) in the reference "
            "frame as three numbers, not all 0 (e.g. [0, -1, 0] for a level camera 0), or leave it out"
        )
    v = v / scale  # no overflow or underflow in the norm
    return v / np.linalg.norm(v)
