"""Rendered frames are geometrically consistent with their annotations (procedural scenes, random rigs)."""

from __future__ import annotations

import numpy as np
import pytest

from posenet.synth.poses import POSTURES, build_pose, sample_params
from posenet.synth.procedural import procedural_frame
from posenet.synth.rig import cam_to_world, random_rig, world_to_cam
from posenet.synth.scene import render_frame
from posenet.synth.skeleton_full import LENGTHS, F, complete_legs, estimate_floor


@pytest.fixture(scope="module")
def rendered():
    rng = np.random.default_rng(7)
    rig = random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 3)
    frames = [procedural_frame(rng, enclose=cam_to_world(rig)[:, :3, 3]) for _ in range(2)]
    return rig, frames, [render_frame(f, rig, rng) for f in frames]


def test_depth_at_a_visible_joint_is_just_in_front_of_it(rendered):
    rig, frames, views = rendered
    T = world_to_cam(rig)
    checked, gaps = 0, []
    for frame, frame_views in zip(frames, views, strict=True):
        for v, vr in enumerate(frame_views):
            for i, person in enumerate(frame.persons):
                kp = vr.keypoints[i]
                pc = person.points[:10] @ T[v, :3, :3].T + T[v, :3, 3]
                vis = kp[:, 2] == 2
                ui, vi = np.round(kp[vis, 0]).astype(int), np.round(kp[vis, 1]).astype(int)
                ideal = vr.ideal_depth[vi, ui]
                own = vr.owner[vi, ui] == i
                gap = pc[vis, 2][own] - ideal[own]
                # Joints sit inside the body: the surface is in front, by less than a limb's thickness.
                assert (gap > 0).all() and (gap < 240).all(), gap
                gaps.append(gap)
                sensed = vr.depth[vi, ui][own].astype(float)
                ok = sensed > 0
                sigma = 1.5e-6 * ideal[own][ok] ** 2
                assert (np.abs(sensed[ok] - ideal[own][ok]) < 6 * sigma + 40).all()
                checked += int(own.sum())
    assert checked > 20
    assert 20 < np.median(np.concatenate(gaps)) < 130, "typical depth of a joint below the skin/clothing"


def test_boxes_hold_the_visible_joints_and_the_visible_pixels(rendered):
    _, frames, views = rendered
    inside = total = 0
    for frame, frame_views in zip(frames, views, strict=True):
        for vr in frame_views:
            for i, box in enumerate(vr.boxes):
                mask = vr.owner == i
                if box is None:
                    continue
                rows, cols = np.nonzero(mask)
                assert (cols.min(), rows.min(), cols.max(), rows.max()) == box
                if frame.persons[i].person_id < 0:
                    continue
                kp = vr.keypoints[i]
                vis = kp[:, 2] == 2
                x0, y0, x1, y1 = box
                ok = (
                    (kp[vis, 0] >= x0 - 1)
                    & (kp[vis, 0] <= x1 + 1)
                    & (kp[vis, 1] >= y0 - 1)
                    & (kp[vis, 1] <= y1 + 1)
                )
                inside += int(ok.sum())
                total += int(vis.sum())
    assert total > 20 and inside / total > 0.95


def test_sensor_images_have_the_right_types_holes_and_range(rendered):
    _, _, views = rendered
    vr = views[0][0]
    assert vr.color.shape == (480, 640, 3) and vr.color.dtype == np.uint8
    assert vr.depth.shape == (480, 640) and vr.depth.dtype == np.uint16
    holes = (vr.depth == 0).mean()
    assert 0.01 < holes < 0.6
    assert (vr.depth[:, :8] == 0).all(), "registered Kinect depth has an invalid left band"
    valid = vr.depth[vr.depth > 0]
    assert valid.min() >= 500 and valid.max() <= 6500


@pytest.mark.parametrize("posture", POSTURES)
def test_procedural_poses_stand_on_the_floor_with_anthropometric_bones(posture):
    rng = np.random.default_rng(POSTURES.index(posture))
    for _ in range(20):
        _, params = sample_params(rng, posture)
        pts = build_pose(params)
        s = params.stature / 1720.0
        assert min(pts[F["left_toe"], 2], pts[F["right_toe"], 2]) > 0
        ankles = min(pts[F["left_ankle"], 2], pts[F["right_ankle"], 2])
        assert ankles == pytest.approx(LENGTHS["ankle_height"] * s)
        upper = np.linalg.norm(pts[F["left_elbow"]] - pts[F["left_shoulder"]])
        assert upper == pytest.approx(LENGTHS["upper_arm"] * s)
        assert pts[F["head"], 2] > pts[F["left_hip"], 2], "nobody is upside down"


def test_leg_completion_reaches_the_floor_and_keeps_the_annotated_points():
    rng = np.random.default_rng(0)
    _, params = sample_params(rng, "standing")
    pts = build_pose(params)
    full = complete_legs(pts[:12], floor_z=0.0)
    assert np.array_equal(full[:12], pts[:12])
    s = np.linalg.norm((pts[2] + pts[3]) / 2 - (pts[4] + pts[5]) / 2) / LENGTHS["trunk"]
    for knee, hip, ankle in ((12, 4, 14), (13, 5, 15)):
        assert full[ankle, 2] == pytest.approx(LENGTHS["ankle_height"] * s, abs=1)
        assert np.linalg.norm(full[knee] - full[hip]) == pytest.approx(LENGTHS["thigh"] * s, rel=0.16)
    # The floor estimate recovers the floor of upright people (heights shifted by 1 m).
    poses = np.stack([build_pose(sample_params(rng, "standing")[1])[:12] for _ in range(30)])
    poses[..., 2] -= 1000
    assert estimate_floor(poses) == pytest.approx(-1000, abs=60)
