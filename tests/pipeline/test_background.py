"""pipeline.background and the tracker's phantom rule: what never moves never becomes a track, and a person who
stands perfectly still for minutes keeps theirs."""

from __future__ import annotations

import numpy as np
import torch

from pipeline.background import DepthBackground, _Rig
from pipeline.track import Tracker, TrackerConfig
from posenet.cameras import Camera
from posenet.scene import SceneView
from posenet.skeleton import NUM_JOINTS
from posenet.synth.poses import PoseParams, build_pose

W, H, WALL_MM = 160, 120, 4000
CAMERA = Camera.create(120.0, 120.0, (W - 1) / 2, (H - 1) / 2)  # the reference camera, looking along z
UP = np.array([0.0, -1.0, 0.0])  # the camera's y axis points down
STANDING = build_pose(PoseParams())[:NUM_JOINTS]  # (J, 3) x forward, y left, z up, floor at 0


def person_at(x_mm: float, depth_mm: float) -> np.ndarray:
    """``(J, 3)`` a standing person's joints in the camera's frame, ``x_mm`` to the right, ``depth_mm`` away, the
    floor 1.2 m below the camera."""
    p = STANDING
    return np.stack([x_mm + p[:, 1], 1200.0 - p[:, 2], depth_mm + p[:, 0]], -1)


def depth_image(*bodies: np.ndarray) -> np.ndarray:
    """``(H, W)`` uint16: a wall at 4 m and in front of it, for each body ``(J, 3)``, its joints' image box (grown
    by a third) at the depth of its front (100 mm before its nearest joint)."""
    depth = np.full((H, W), WALL_MM, np.uint16)
    for body in bodies:
        uv = CAMERA.project(torch.from_numpy(body)).numpy()
        (u0, v0), (u1, v1) = uv.min(0), uv.max(0)
        du, dv = (u1 - u0) / 3, (v1 - v0) / 3
        rows = slice(max(int(v0 - dv), 0), min(int(v1 + dv) + 1, H))
        cols = slice(max(int(u0 - du), 0), min(int(u1 + du) + 1, W))
        depth[rows, cols] = np.minimum(depth[rows, cols], int(body[:, 2].min() - 100))
    return depth


def views(*bodies: np.ndarray) -> list[SceneView]:
    return [SceneView(None, depth_image(*bodies), CAMERA)]


def test_the_numpy_projection_equals_the_camera_s_with_distortion():
    cam = Camera.create(500.0, 480.0, 320.0, 240.0, distortion=[0.1, -0.05, 0.001, -0.002, 0.02])
    T = np.eye(4)
    T[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    T[:3, 3] = [2000.0, 100.0, 1500.0]
    moved = Camera.create(500.0, 480.0, 320.0, 240.0, extrinsics=T)
    points = np.random.default_rng(0).uniform(-800, 800, (20, 3)) + [0, 0, 3000]
    rig = _Rig([SceneView(None, np.zeros((4, 4), np.uint16), c) for c in (cam, moved)])
    uv, z = rig.project(points)
    for v, c in enumerate((cam, moved)):
        np.testing.assert_allclose(uv[v], c.project(torch.from_numpy(points)).numpy(), atol=1e-6)
        np.testing.assert_allclose(z[v], c.to_camera(torch.from_numpy(points)).numpy()[:, 2], atol=1e-6)


def test_a_person_is_in_front_of_the_learned_wall_and_not_of_a_background_that_holds_them():
    person = person_at(0.0, 2500.0)[None]
    empty = DepthBackground()
    empty.update(views(), 0.0)
    assert empty.foreground(person, views(person[0])) == 1.0
    holding = DepthBackground()  # the first frame is the background: whoever is in it is part of it
    holding.update(views(person[0]), 0.0)
    assert holding.foreground(person, views(person[0])) == 0.0
    # Someone in front hides the person: the joints they hide say nothing (NaN: no torso joint seen).
    blocker = person_at(0.0, 1200.0)
    assert np.isnan(empty.foreground(person, views(person[0], blocker)))
    assert np.isnan(DepthBackground().foreground(person, views(person[0])))  # nothing learned yet


def test_what_never_moves_never_becomes_a_track_without_views_it_would():
    # A coat on a hook, from the stream's first frame: an upright skeleton that the pose network is unsure of
    # (spread 450 mm), still but for the network's jitter, for 20 s at 15 fps.
    coat = person_at(-600.0, 3000.0)
    rng = np.random.default_rng(0)
    with_views, without = Tracker(), Tracker()
    for f in range(300):
        joints = (coat + rng.normal(0, 30, coat.shape))[None]
        spread = np.full((1, NUM_JOINTS), 450.0)
        a = with_views.update(joints, spread, f / 15, up=UP, views=views(coat))
        b = without.update(joints, spread, f / 15, up=UP)
        assert a[0].track_id is None
    assert b[0].track_id is not None  # the same skeletons without the room's depth: a track


def test_a_person_who_walks_in_and_stands_still_for_minutes_keeps_their_track():
    # Walks in from the right at 1 m/s for 2 s, then stands perfectly still (joint noise aside) for 5 minutes: 5
    # frames a second for the first 4 s, then one a second. The background never absorbs them: their pixels are kept while
    # their track is confirmed, and the track keeps its id to the end.
    rng = np.random.default_rng(1)
    tracker, ids = Tracker(), []
    times = np.concatenate([np.arange(20) / 5, 4 + np.arange(300)])
    for t in times:
        truth = person_at(max(2000.0 - 1000.0 * t, 0.0), 2500.0)
        joints = (truth + rng.normal(0, 30, truth.shape))[None]
        out = tracker.update(joints, np.full((1, NUM_JOINTS), 300.0), t, up=UP, views=views(truth))
        ids.append(out[0].track_id)
    assert ids[:2] == [None, None] and set(ids[2:]) == {0}  # confirmed on its third frame, never lost
    assert tracker.background.foreground(truth[None], views(truth)) == 1.0  # still in front of the background
    # Untracked, the same still person is absorbed within minutes (time constant 2 min): after 1 minute it is
    # still in front, after 10 it is background.
    untracked = DepthBackground()
    untracked.update(views(), 0.0)
    for t in range(1, 601):
        untracked.update(views(truth), float(t))
        if t == 60:
            assert untracked.foreground(truth[None], views(truth)) == 1.0
    assert untracked.foreground(truth[None], views(truth)) == 0.0


def test_a_still_person_from_the_first_frame_is_confirmed_by_a_sure_upright_pose_or_by_moving():
    rng = np.random.default_rng(2)

    def first_id(spread_mm: float, walk_mm_s: float, frames: int = 150) -> int | None:
        tracker = Tracker()
        for f in range(frames):
            truth = person_at(walk_mm_s * f / 15, 2500.0)
            joints = (truth + rng.normal(0, 20, truth.shape))[None]
            out = tracker.update(
                joints, np.full((1, NUM_JOINTS), spread_mm), f / 15, up=UP, views=views(truth)
            )
            if out[0].track_id is not None:
                return f
        return None

    assert first_id(TrackerConfig().pose_spread_mm - 50, 0.0) == 2  # sure and upright: at once
    assert first_id(450.0, 0.0) is None  # unsure and still from the start: background
    moved_at = first_id(450.0, 500.0)  # unsure, but walks off at 0.5 m/s: once 30 cm from where it was born
    assert moved_at is not None and 8 <= moved_at <= 15


def test_a_track_that_passes_from_its_person_to_a_coat_ends_within_a_second():
    # A coat hangs on a hook from the first frame (30 cm behind where a person will stand). A person walks in
    # and stands in front of it; after 4 s they leave, and the pose network now gives the coat an unsure
    # skeleton within the track's gate: the track would go on on nobody. It ends after park_s (0.5 s) of frames
    # without a sign of life (its 30 cm step onto the coat counts as a move and starts them again: 0.8 s in
    # all), and nothing confirms the coat again.
    coat = person_at(-300.0, 2800.0)
    rng = np.random.default_rng(3)

    def ids(config: TrackerConfig) -> list[int | None]:
        tracker, out = Tracker(config), []
        for f in range(15 * 8):
            t = f / 15
            if t < 4:
                truth, spread = person_at(max(1700.0 - 1000.0 * t, -300.0), 2500.0), 250.0
                seen = views(truth, coat)
            else:
                truth, spread, seen = coat, 500.0, views(coat)
            joints = (truth + rng.normal(0, 20, truth.shape))[None]
            out.append(
                tracker.update(joints, np.full((1, NUM_JOINTS), spread), t, up=UP, views=seen)[0].track_id
            )
        return out

    parked = ids(TrackerConfig())
    assert set(parked[3:60]) == {0}  # the person, from their third frame
    assert set(parked[60 + 15 :]) == {None}  # on the coat for less than the 1 s allowed, then none
    assert set(ids(TrackerConfig(park_s=None))[60:]) == {0}  # without the rule the track stays on the coat


def test_a_phantom_seen_every_other_frame_is_parked_within_0_7_s_and_a_hidden_person_keeps_their_id():
    # A person walks in and stands in front of a coat; after 4 s they leave and the pose network gives the coat an
    # unsure skeleton in every other frame. The stillness clock runs in the frames between (park_suspends), so the
    # track is parked within 0.7 s; before, it ran only in the frames with a skeleton (about 1 s).
    coat = person_at(-300.0, 2800.0)
    rng = np.random.default_rng(5)

    def parked_after_s(config: TrackerConfig) -> float:
        tracker = Tracker(config)
        for f in range(15 * 8):
            t = f / 15
            if t < 4:
                truth, spread, seen = person_at(max(1700.0 - 1000.0 * t, -300.0), 2500.0), 250.0, True
            else:
                truth, spread, seen = coat, 500.0, f % 2 == 0
            joints = (truth + rng.normal(0, 20, truth.shape))[None][:seen]
            out = tracker.update(joints, np.full((len(joints), NUM_JOINTS), spread), t, up=UP, views=views(coat))
            if t >= 4 and out and out[0].track_id is None:
                return t - 4
        return float("inf")

    assert parked_after_s(TrackerConfig()) <= 0.7  # its 30 cm step onto the coat counts as one move
    assert parked_after_s(TrackerConfig(park_suspends=False, park_recovery=float("inf"))) >= 0.9

    # A person walking across the room is hidden from every view for 1.2 s (no skeleton: the clock runs past
    # park_s) and walks on: the parked track is suspended, not ended, and answers them with their id again once
    # their moves have wound the clock back under park_s.
    tracker, ids, parked = Tracker(), [], []
    for f in range(15 * 6):
        t = f / 15
        truth = person_at(-1500.0 + 500.0 * t, 2500.0)
        hidden = 2.0 <= t < 3.2
        joints = np.zeros((0, NUM_JOINTS, 3)) if hidden else (truth + rng.normal(0, 20, truth.shape))[None]
        out = tracker.update(joints, np.full((len(joints), NUM_JOINTS), 250.0), t, up=UP, views=views(truth))
        ids.append(None if hidden else out[0].track_id)
        parked.append(not hidden and out[0].parked)
    after = [i for i in ids[int(3.2 * 15) :]]
    assert set(ids[3:30]) == {0} and set(after) <= {None, 0}
    # answered without an id while parked (TrackedPerson.parked), not as a tentative track's
    assert [i is None for i in after] == parked[int(3.2 * 15) :]
    assert after.index(0) <= 8 and set(after[8:]) == {0}  # back within 0.53 s, the same id
