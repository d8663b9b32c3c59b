"""How many views support each 3D pose: the grouping of MVOR's per-support table.

A view *supports* a pose when the person is visible in it, i.e. the view has a box with the pose's
``person_id`` (Kadkhodamohammadi 2017; the paper's last table). This module is the single place that counts
it: the reader (``Sample.support``) and the evaluator (the per-support table) both call :func:`pose_support`.

The counting rule reproduces MVOR's published numbers (132 / 426 / 503 poses with 1 / 2 / 3 supporting views):
it counts the **boxes** that carry the pose's ``person_id`` over the frame's views, as MVOR's
``lib/show_stats.py`` does. Counting distinct *views* instead gives 132 / 428 / 501. The two rules differ on
exactly one frame of the real file (day 4, frame 38: poses 636 and 637), where two different persons are both
labelled ``person_id`` 0 and camera 3 holds two boxes with id 0, so each of the two poses counts 3 boxes but
only 2 views. Boxes without an identity (``person_id`` -1) never support a pose. See ``docs/CONVENTIONS.md``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence


def boxes_per_person(annotations: Sequence[Mapping]) -> Counter:
    """Count the boxes per ``(image_id, person_id)`` in MVOR's 2D ``annotations`` list (ids -1 left out)."""
    return Counter((a["image_id"], a["person_id"]) for a in annotations if a["person_id"] >= 0)


def frame_image_ids(multiview_images: Sequence[Mapping]) -> dict[str, list]:
    """Map each multi-view id to the image ids of its views (MVOR's ``multiview_images``)."""
    return {mv["id"]: [im["id"] for im in mv["images"]] for mv in multiview_images}


def pose_support(gt: Mapping, counts: Counter | None = None) -> list[int]:
    """The number of supporting views of every pose in ``gt["annotations3D"]``, in that list's order.

    Args:
        gt: an MVOR-format annotation dict (``multiview_images``, ``annotations``, ``annotations3D``).
        counts: :func:`boxes_per_person` of ``gt["annotations"]``, if already computed.

    Raises:
        ValueError: a 3D pose refers to a multi-view id that ``multiview_images`` does not list.
    """
    frames = frame_image_ids(gt["multiview_images"])
    counts = boxes_per_person(gt["annotations"]) if counts is None else counts
    support = []
    for i, pose in enumerate(gt["annotations3D"]):
        image_ids = frames.get(pose["image_ids"])
        if image_ids is None:
            raise ValueError(
                f"annotations3D[{i}] refers to multi-view frame {pose['image_ids']!r}, "
                "which multiview_images does not list"
            )
        pid = pose["person_id"]
        support.append(0 if pid < 0 else sum(counts[(image_id, pid)] for image_id in image_ids))
    return support
