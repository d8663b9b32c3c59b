"""What a person looks like, for telling people apart over time: a colour histogram of their boxes.

A track whose person is out of every view for longer than the tracker coasts ends, and the person comes back under
a new id (``posenet.track``). Their skeleton cannot say who they are (the bone lengths the tracker keeps are too
alike between adults, docs/RESULTS.md, session 26), their clothes often can: scrubs, gowns and caps differ in
colour between people and roles.

:func:`person_appearance` describes one person of a frame by a hue-saturation histogram (``HUE_BINS`` x
``SAT_BINS``, summing to 1) of the pixels of the middle of each of their boxes (the central half of the width, from
an eighth below the top to a quarter above the bottom: the trunk and upper legs, little background) whose depth
lies within ``DEPTH_BAND_MM`` of that region's median depth (the person, not what is behind them), averaged over
the views. :func:`appearance_distance` compares two of them: the Hellinger distance, 0 for equal histograms, 1 for
histograms without a common bin.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

HUE_BINS, SAT_BINS = 12, 4
APPEARANCE_SIZE = HUE_BINS * SAT_BINS
DEPTH_BAND_MM = 300.0
MIN_PIXELS = 30  # a box region with fewer pixels of the person says nothing


def box_histogram(color: np.ndarray, depth: np.ndarray, box) -> np.ndarray | None:
    """``(APPEARANCE_SIZE,)`` hue-saturation histogram (sums to 1) of the person in ``box`` (xyxy pixels of
    ``color (H, W, 3)`` RGB uint8 and ``depth (H, W)`` mm), or None when the region holds too few of their pixels."""
    h, w = depth.shape
    x0, y0, x1, y1 = (float(v) for v in box)
    bw, bh = x1 - x0, y1 - y0
    cx0, cx1 = int(max(x0 + bw / 4, 0)), int(min(x1 - bw / 4, w))
    cy0, cy1 = int(max(y0 + bh / 8, 0)), int(min(y1 - bh / 4, h))
    if cx1 - cx0 < 2 or cy1 - cy0 < 2:
        return None
    d = depth[cy0:cy1, cx0:cx1].astype(np.float32)
    valid = d > 0
    if np.count_nonzero(valid) < MIN_PIXELS:
        return None
    person = valid & (np.abs(d - np.median(d[valid])) <= DEPTH_BAND_MM)
    if np.count_nonzero(person) < MIN_PIXELS:
        return None
    hsv = cv2.cvtColor(np.ascontiguousarray(color[cy0:cy1, cx0:cx1]), cv2.COLOR_RGB2HSV)
    hist = cv2.calcHist([hsv], [0, 1], person.astype(np.uint8), [HUE_BINS, SAT_BINS], [0, 180, 0, 256])
    return (hist.ravel() / hist.sum()).astype(np.float64)


def person_appearance(views: Sequence, boxes: Sequence) -> np.ndarray:
    """``(APPEARANCE_SIZE,)`` one person's histogram, the mean over the views where it could be read, or all NaN
    when none could (no colour, no box, too few pixels). ``views``: V ``posenet.scene.SceneView`` s; ``boxes``: V
    entries, an xyxy box in that view's pixels or None."""
    hists = [
        h
        for view, box in zip(views, boxes, strict=True)
        if box is not None and view.color is not None
        for h in [box_histogram(view.color, view.depth, box)]
        if h is not None
    ]
    if not hists:
        return np.full(APPEARANCE_SIZE, np.nan)
    return np.mean(hists, axis=0)


def appearance_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hellinger distance between histograms ``a (..., D)`` and ``b (..., D)`` (broadcast): ``sqrt(1 - sum
    sqrt(a b))``, in [0, 1]; NaN where either is NaN."""
    bc = np.sqrt(np.clip(a, 0, None) * np.clip(b, 0, None)).sum(-1)
    return np.sqrt(np.clip(1.0 - bc, 0.0, 1.0))
