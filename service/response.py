"""From the pipeline's result to the ``SceneOut`` body: checked, in the client's terms, with the reasons for
anything left out.

- Every number is checked to be finite before it is sent: the schema promises numbers, and a NaN would be
  written as ``null``. A non-finite estimate is answered 422 with what to check (the inputs are bounded, so
  it should not happen; if it does, the cause is in the calibration or the depth, not in the server).
- Boxes are reported as the client sent them. Validation clips a box that is partly outside its image for
  the computation (``ValidatedScene.sent_boxes`` keeps the originals).
- ``notes`` say why persons are missing or doubtful: a view without valid depth, a person (by id) whose boxes
  hold no valid depth, or a one-view person whose skeleton has no person's size (``posenet.net.plausibility``).
"""

from __future__ import annotations

import time

import numpy as np

from pipeline.two_stage import PersonResult, SceneResult
from posenet.boxes import PersonBoxes, hull
from posenet.net.plausibility import ONE_VIEW_CAP, body_scale, implausible
from posenet.skeleton import JOINTS
from service.errors import InputError
from service.schemas import Joint, Person, SceneOut, Support, Timings
from service.validation import ValidatedScene


def _sent_boxes(result: SceneResult, scene: ValidatedScene) -> PersonBoxes:
    """The persons' boxes in the client's terms: reference boxes as sent, not as validation clipped them (their
    hull where a person holds several); detected boxes brought from the pixels they were decoded at back to the
    pixels of the images as sent."""
    if scene.boxes is None:
        return result.boxes.rescaled(scene.reduced) if scene.reduced else result.boxes
    sent = PersonBoxes(result.boxes.boxes.copy(), result.boxes.has_box, result.boxes.ids, result.boxes.scores)
    for p, person in enumerate(result.persons):
        for v, held in enumerate(person.box_indices):
            if held:
                sent.boxes[p, v] = hull(np.asarray(scene.sent_boxes[v], np.float64)[list(held)])
    return sent


def _notes(persons: list[PersonResult], scene: ValidatedScene) -> list[str]:
    notes = [
        f"depth_{v} holds no valid depth (every pixel is 0, unknown): view {v} supports nobody"
        for v, view in enumerate(scene.views)
        if not view.depth.any()
    ] + list(scene.notes)
    if persons:
        joints = np.stack([p.joints for p in persons])
        scales = body_scale(joints)
        flagged = implausible(joints, [len(p.support) for p in persons], scales)
        notes += [
            f"person {p.id} is seen by one view only and its skeleton is {scale:.0%} of an adult's size: its depth "
            "is likely not the person's (the heatmaps lie on what is behind or beside them), so its confidence is "
            f"capped at {ONE_VIEW_CAP}; a second view of this person, or a box that fits them more tightly, would "
            "settle it"
            for p, scale, bad in zip(persons, scales, flagged, strict=True)
            if bad
        ]
    if scene.person_ids is not None:
        found = {p.id for p in persons}
        missing = sorted({int(i) for ids in scene.person_ids for i in ids} - found)
        notes += [
            f"person {pid} is left out: its boxes hold no valid depth (0 = unknown) in any view, so nothing "
            "can be lifted to 3D"
            for pid in missing
        ]
    return notes


def _checked(person: PersonResult, boxes: PersonBoxes, p: int) -> Person:
    """Person ``p`` of the response, its boxes ``boxes``' row ``p``."""
    if not (np.isfinite(person.joints).all() and np.isfinite(person.spread_mm).all()):
        raise InputError(
            f"the 3D estimate of person {person.id} is not finite: check the cameras (fx, fy, distortion, "
            "extrinsics with translations in mm) and depth_scale_mm"
        )
    return Person(
        id=person.id,
        joints=[
            Joint(name=name, position=[float(x) for x in xyz], confidence=float(c), spread_mm=float(s))
            for name, xyz, c, s in zip(
                JOINTS, person.joints, person.confidence, person.spread_mm, strict=True
            )
        ],
        views=[
            Support(view=v, box=[float(x) for x in boxes.boxes[p, v]], score=boxes.score(p, v))
            for v in boxes.support(p)
        ],
    )


def scene_out(result: SceneResult, scene: ValidatedScene, decode_ms: float) -> SceneOut:
    """The checked response of ``result``, its ``encode`` and ``total`` timings still 0 (:func:`serialise`)."""
    boxes = _sent_boxes(result, scene)
    return SceneOut(
        mode=result.mode,
        persons=[_checked(person, boxes, p) for p, person in enumerate(result.persons)],
        notes=_notes(result.persons, scene),
        timings=Timings(decode=decode_ms, encode=0.0, total=0.0, **result.timings),
    )


def serialise(out: SceneOut, t0: float, t_start: float) -> bytes:
    """``out`` as JSON bytes with its ``encode`` (since ``t0``) and ``total`` (since ``t_start``) timings; both
    are perf_counter readings."""
    out.model_dump_json()
    # The encode time is measured on a first serialisation; the response carries it in the second.
    out.timings.encode = (time.perf_counter() - t0) * 1e3
    out.timings.total = (time.perf_counter() - t_start) * 1e3
    return out.model_dump_json().encode()


def encode(result: SceneResult, scene: ValidatedScene, decode_ms: float, t_start: float) -> bytes:
    """The response body of ``result``; ``t_start``: the request's perf_counter start (for ``total``)."""
    t0 = time.perf_counter()
    return serialise(scene_out(result, scene, decode_ms), t0, t_start)
