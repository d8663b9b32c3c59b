"""pipeline.track's body signature: a person who leaves every view and comes back gets their id again when their
size says who they are, and someone of another size does not."""

from __future__ import annotations

import numpy as np

from pipeline.track import Tracker, TrackerConfig
from posenet.skeleton import NUM_JOINTS
from posenet.synth.poses import PoseParams, build_pose

FPS = 15.0
REID = TrackerConfig(reid_s=60.0)


def body(stature_mm: float, x_mm: float, y_mm: float) -> np.ndarray:
    """``(J, 3)`` a standing person of ``stature_mm`` at (x, y) on the floor, z up."""
    return build_pose(PoseParams(stature=stature_mm))[:NUM_JOINTS] + [x_mm, y_mm, 0.0]


def run(config: TrackerConfig, comer_stature: float, seed: int = 0) -> list[tuple[int | None, int | None]]:
    """A tall person (1.95 m) and a short one (1.50 m) walk for 3 s; the tall one leaves every view for 4 s (longer
    than a track coasts) and someone of ``comer_stature`` comes in 2 m from where they left. Per frame, the ids
    of the short person and of whoever is at the tall person's place."""
    rng = np.random.default_rng(seed)
    tracker, out = Tracker(config), []
    for f in range(int(FPS * 10)):
        t = f / FPS
        short = body(1500.0, 3000.0 - 300 * t, -1500.0)
        people = [short]
        if t < 3:
            people.append(body(1950.0, 500 * t, 1500.0))
        elif t >= 7:
            people.append(body(comer_stature, 3500.0 - 500 * (t - 7), 1500.0))
        joints = np.array(people) + rng.normal(0, 20, (len(people), NUM_JOINTS, 3))
        tracked = tracker.update(joints, np.full((len(people), NUM_JOINTS), 200.0), t)
        out.append((tracked[0].track_id, tracked[1].track_id if len(tracked) > 1 else None))
    return out


def test_a_person_back_after_leaving_every_view_gets_their_id_again():
    frames = run(REID, comer_stature=1950.0)
    assert len({a for a, _ in frames[3:]}) == 1  # the short person keeps one id throughout
    tall = frames[10][1]
    assert tall is not None and frames[-1][1] == tall  # the same id after 4 s away
    assert run(TrackerConfig(), comer_stature=1950.0)[-1][1] not in (tall, None)  # off: a new id


def test_someone_of_another_size_gets_a_new_id():
    frames = run(REID, comer_stature=1600.0)
    assert frames[-1][1] is not None and frames[-1][1] not in (frames[10][0], frames[10][1])
