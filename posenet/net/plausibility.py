"""Whether a skeleton has a person's size: the check that keeps a one-view estimate from being confidently wrong.

With several views, heatmap mass that falls on the wall behind a person lifts to points no other view agrees
with, and the aggregation outweighs it. With one view nothing does: a narrow box whose heatmaps spill onto what
is behind or beside the person lifts the skeleton there, often collapsed onto one small patch, with a tight
spread and so a high confidence. Its bones then no longer have a person's lengths. :func:`body_scale` is a
skeleton's size against an adult's (the median ratio of its bone lengths to ``REFERENCE_BONES_MM``), and
:func:`implausible` marks the one-view persons below ``MIN_ONE_VIEW_SCALE``: their confidence is capped at
``ONE_VIEW_CAP`` (``posenet.net.calibration``) and the service says so in its notes.

Chosen on 80 procedural frames of unseen random rigs in the alt look (seed 77, ``benchmarks/one_view.py``): of 30
one-view persons, every one within 10 cm had a scale of 0.84 or more; the four more than 50 cm off had 0.01, 0.53,
0.65 and 0.84 (the last already below 0.5 confidence). Checked on seed 79, which chose nothing (docs/RESULTS.md).
"""

from __future__ import annotations

import numpy as np
import torch

from posenet.skeleton import BONES

# Median bone lengths (mm, posenet.skeleton.BONES order) over the 1,061 annotated 3D poses of MVOR (real staff).
REFERENCE_BONES_MM = (116.0, 191.0, 254.0, 407.0, 191.0, 190.0, 411.0, 248.0, 185.0, 319.0)
MIN_ONE_VIEW_SCALE = 0.75
ONE_VIEW_CAP = 0.2


def body_scale(joints) -> np.ndarray:
    """The size of skeletons ``joints (..., J, 3)`` mm against an adult's: the median over the bones of length
    over ``REFERENCE_BONES_MM``; (...) floats (1 is an adult of median build, 0 a skeleton collapsed to a point)."""
    j = torch.as_tensor(joints, dtype=torch.float64)
    i, k = zip(*BONES, strict=True)
    lengths = (j[..., list(i), :] - j[..., list(k), :]).norm(dim=-1)  # (..., B)
    ref = torch.tensor(REFERENCE_BONES_MM, dtype=torch.float64)
    return (lengths / ref).median(dim=-1).values.numpy()


def implausible(joints, support, scale: np.ndarray | None = None) -> np.ndarray:
    """(...) bool: persons seen by one view (``support (...)``) whose skeleton ``joints (..., J, 3)`` is less than
    ``MIN_ONE_VIEW_SCALE`` of an adult's size (``scale``: their :func:`body_scale`, when already known)."""
    scale = body_scale(joints) if scale is None else scale
    return (np.asarray(support) == 1) & (scale < MIN_ONE_VIEW_SCALE)
