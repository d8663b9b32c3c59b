"""The twin's building blocks recover their inputs: table fit, bystanders, occluders, box assignment."""

from __future__ import annotations

import numpy as np
import pytest

from posenet.synth.boxes import project_boxes
from posenet.synth.bystanders import floor_position, merge_positions
from posenet.synth.poses import build_pose, place, sample_params
from posenet.synth.procedural import procedural_frame
from posenet.synth.rig import cam_to_world, random_rig
from posenet.synth.scene import Person, render_frame
from posenet.synth.twin import _cuboid_corners, add_occluders, assign_boxes, fit_table


@pytest.fixture(scope="module")
def rig():
    rng = np.random.default_rng(2)
    return random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 3)


def test_table_fit_recovers_a_known_table_from_its_boxes(rig):
    truth = np.array([[250.0, -180.0]]), np.array([0.6]), np.array([930.0])
    boxes = project_boxes(rig, _cuboid_corners(*truth))[:, 0]  # (V, 4)
    (centre, yaw), iou = fit_table(
        rig, [(v, boxes[v]) for v in range(len(rig))], np.random.default_rng(0)
    )
    assert iou > 0.9
    assert np.linalg.norm(centre[:2] - truth[0][0]) < 150
    assert min(abs(yaw - 0.6) % np.pi, np.pi - abs(yaw - 0.6) % np.pi) < 0.15  # the cuboid is symmetric


def test_bystander_floor_position_inverts_the_projection_of_a_head_top(rig):
    for xy in ([300.0, 200.0], [-900.0, 600.0]):
        head_top = np.array([[[*xy, 1700.0], [*xy, 1700.0]]])
        feet = np.array([[[*xy, 0.0], [*xy, 0.0]]])
        for v in range(len(rig)):
            u, top = project_boxes(rig, head_top)[v, 0, :2]
            bottom = project_boxes(rig, feet)[v, 0, 1]
            found = floor_position(rig, v, np.array([u - 30, top, u + 30, bottom]))
            assert np.allclose(found, xy, atol=1.0)
    clusters = merge_positions([(0, np.array([0.0, 0]), None), (1, np.array([200.0, 0]), None),
                                (0, np.array([3000.0, 0]), None)])  # fmt: skip
    assert len(clusters) == 2 and np.allclose(clusters[0][0], [100, 0])


def test_box_assignment_gives_each_real_box_to_the_best_fitting_person(rig):
    rng = np.random.default_rng(0)
    frame = procedural_frame(rng, patient_prob=0.0, enclose=cam_to_world(rig)[:, :3, 3])
    a = place(build_pose(sample_params(rng, "standing")[1]), np.array([-800.0, 0]), 0.0)
    b = place(build_pose(sample_params(rng, "standing")[1]), np.array([900.0, 300]), 0.0)
    frame.persons[:] = [Person(p, frame.persons[0].outfit, 7) for p in (a, b)]  # MVOR reuses id 7
    real_b = project_boxes(rig, b[None, :12])[0, 0]
    show = assign_boxes(rig, frame.persons, {(0, 7): [real_b], (1, 7): [np.zeros(4), np.ones(4)]})
    assert (0, 1) in show and (0, 0) not in show  # one box in view 0: the person it fits
    assert {(1, 0), (1, 1)} <= show  # two boxes in view 1: both people


def test_occluders_hide_exactly_the_people_who_must_be_hidden(rig):
    rng = np.random.default_rng(5)
    frame = procedural_frame(rng, patient_prob=0.0, enclose=cam_to_world(rig)[:, :3, 3])
    before = render_frame(frame, rig, np.random.default_rng(0))
    visible = {(v, i) for v, vr in enumerate(before) for i, b in enumerate(vr.boxes) if b is not None}
    assert len(visible) >= 3
    hide = {sorted(visible)[0]}
    stats = add_occluders(frame, rig, hide, visible - hide, ceiling=2900.0)
    after = render_frame(frame, rig, np.random.default_rng(0))
    now = {(v, i) for v, vr in enumerate(after) for i, b in enumerate(vr.boxes) if b is not None}
    assert not hide & now
    assert stats["occluder"] + stats["not_drawn"] == 1
    assert len((visible - hide) - now) <= 1  # the monitor may cost at most one other box
