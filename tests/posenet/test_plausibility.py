"""A skeleton's size against an adult's, and the cap it puts on a one-view person's confidence."""

from __future__ import annotations

import numpy as np
import torch

from posenet.net.calibration import Calibration
from posenet.net.plausibility import ONE_VIEW_CAP, REFERENCE_BONES_MM, body_scale, implausible
from posenet.skeleton import BONES, NUM_JOINTS


def adult(scale: float = 1.0) -> np.ndarray:
    """A skeleton (J, 3) mm whose every bone has ``scale`` times its reference length (a tree walk from the head;
    the hips' bone closes a loop, so it is only near its length)."""
    rng = np.random.default_rng(0)
    joints = np.full((NUM_JOINTS, 3), np.nan)
    joints[0] = [0.0, 0.0, 3000.0]
    pending = list(zip(BONES, REFERENCE_BONES_MM, strict=True))
    while pending:
        (i, k), length = pending.pop(0)
        if np.isnan(joints[i]).any() and np.isnan(joints[k]).any():
            pending.append(((i, k), length))
            continue
        if not np.isnan(joints[k]).any() and not np.isnan(joints[i]).any():
            continue
        a, b = (i, k) if not np.isnan(joints[i]).any() else (k, i)
        d = rng.normal(size=3)
        joints[b] = joints[a] + scale * length * d / np.linalg.norm(d)
    return joints


def test_an_adult_has_scale_one_and_scales_with_its_bones():
    assert abs(float(body_scale(adult())) - 1.0) < 0.05
    assert abs(float(body_scale(adult(2.0))) - 2.0) < 0.1
    assert float(body_scale(np.zeros((NUM_JOINTS, 3)))) == 0.0
    both = body_scale(np.stack([adult(), adult(0.5)]))  # batched
    assert both.shape == (2,) and both[1] < 0.6 < 0.95 < both[0]


def test_only_small_one_view_skeletons_are_implausible():
    joints = np.stack([adult(), adult(0.3), adult(0.3)])
    assert implausible(joints, [1, 1, 2]).tolist() == [False, True, False]


def test_the_calibration_caps_them_and_leaves_everyone_else():
    cal = Calibration.from_config({})
    spread = torch.full((3, NUM_JOINTS), 20.0)
    support = torch.tensor([1, 1, 2])
    joints = torch.as_tensor(np.stack([adult(), adult(0.3), adult(0.3)]))
    plain = cal(spread, support)
    capped = cal(spread, support, joints)
    assert (plain[1] > ONE_VIEW_CAP).all()  # a tight spread alone reads as a sure person
    assert torch.equal(capped[[0, 2]], plain[[0, 2]])
    assert (capped[1] <= ONE_VIEW_CAP).all()
