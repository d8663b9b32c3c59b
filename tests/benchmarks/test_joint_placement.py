"""benchmarks/joint_placement.py: a constant placement of the joints inside the body is found and removed."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from posenet.skeleton import NUM_JOINTS
from posenet.synth.poses import PoseParams, build_pose

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from joint_placement import SIDE, TYPE_OF, corrected, errors, fit_offsets, frames  # noqa: E402


def poses(n: int, seed: int) -> np.ndarray:
    """``(n, J, 3)`` a standing person turned about the vertical and moved around the room, mm."""
    rng = np.random.default_rng(seed)
    template = build_pose(PoseParams())[:NUM_JOINTS]
    out = []
    for a, x, y in zip(
        rng.uniform(0, 2 * np.pi, n), rng.uniform(-2000, 2000, n), rng.uniform(-2000, 2000, n), strict=True
    ):
        c, s = np.cos(a), np.sin(a)
        out.append(template @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T + [x, y, 0])
    return np.array(out)


def test_a_constant_placement_is_found_in_the_body_frame_and_removed():
    """Predictions that put every joint type a fixed amount off along the body's own axes (left and right
    mirrored), plus noise: the fitted offsets are that amount, and adding them back leaves the noise only."""
    offsets = np.zeros((6, 3))
    offsets[2] = (-10.0, 25.0, 30.0)  # shoulders: back, outward, up
    offsets[3] = (10.0, 20.0, -60.0)  # hips: forward, outward, down
    rng = np.random.default_rng(0)
    truth = poses(200, 1)
    local = offsets[TYPE_OF][None].repeat(len(truth), 0)
    local[..., 1] *= SIDE
    pred = truth - np.einsum("nab,nja->njb", frames(truth), local) + rng.normal(0, 5, truth.shape)
    valid = np.ones(pred.shape[:2], bool)
    found = fit_offsets(pred, truth, valid)
    assert np.abs(found - offsets).max() < 8, found.round(1)  # the prediction's frame is slightly turned
    raw, fixed = errors(pred, truth, valid), errors(corrected(pred, found), truth, valid)
    assert raw["hip"] > 5.0 and fixed["hip"] < 1.5 and fixed["overall"] < 0.4 * raw["overall"]
    # Without any placement error there is nothing to find: the correction changes next to nothing.
    plain = truth + rng.normal(0, 5, truth.shape)
    again = errors(corrected(plain, fit_offsets(plain, truth, valid)), truth, valid)
    assert abs(again["overall"] - errors(plain, truth, valid)["overall"]) < 0.1
