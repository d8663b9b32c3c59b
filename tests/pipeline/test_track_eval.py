"""pipeline.track_eval's HOTA and phantom figures against values worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.track_eval import SequenceFrame, TrackedPerson, hota, phantoms, score
from posenet.skeleton import NUM_JOINTS

FPS = 15.0


def walkers(frames: int, persons: int = 2) -> np.ndarray:
    """``(N, K, J, 3)`` persons 2 m apart walking along x at 1 m/s; joints spread over 60 cm so none coincide."""
    t = np.arange(frames) / FPS
    body = np.linspace(0, 600, NUM_JOINTS)[:, None] * np.array([0.0, 0.2, 1.0])  # (J, 3)
    out = np.zeros((frames, persons, NUM_JOINTS, 3))
    for k in range(persons):
        out[:, k] = body[None] + np.stack([1000 * t, np.full_like(t, 2000.0 * k), 0 * t], -1)[:, None]
    return out


def frames_of(truth: np.ndarray, ignore: np.ndarray | None = None) -> list[SequenceFrame]:
    """The ground truth ``(N, K, J, 3)`` as frames (ids 0..K-1); ``ignore (N, I, J, 3)``: persons in view but not
    annotated."""
    empty = np.zeros((0, NUM_JOINTS, 3))
    return [
        SequenceFrame(f / FPS, np.arange(truth.shape[1]), truth[f], empty, np.zeros((0, NUM_JOINTS)),
                      ignore_joints=None if ignore is None else ignore[f])
        for f in range(len(truth))
    ]  # fmt: skip


def tracks(joints: dict[int, np.ndarray], seed: int = 0) -> dict[int, TrackedPerson]:
    """Tracks whose smoothed joints are ``joints`` (``{track_id: (J, 3)}``), their raw ones 2 cm noisier."""
    rng = np.random.default_rng(seed)
    return {t: TrackedPerson(t, j + rng.normal(0, 20, j.shape), j.copy()) for t, j in joints.items()}


def test_hota_is_one_for_perfect_tracks_and_the_square_root_of_a_third_for_a_swap_halfway():
    truth = walkers(60)
    frames = frames_of(truth)
    perfect = [tracks({7: truth[f, 0], 9: truth[f, 1]}) for f in range(60)]
    figures = hota(frames, perfect)
    assert figures.pop("hota_similarity") == "max(0, 1 - mean joint distance / 500 mm)"
    assert figures == pytest.approx({"hota": 1.0, "deta": 1.0, "assa": 1.0, "hota_at_half": 1.0}, abs=1e-9)
    # Ids swap at frame 30: each person shares 30 frames with each of two tracks of 60 frames, an association
    # IoU of 30 / (60 + 60 - 30) = 1/3 for every match; detection is perfect, so HOTA = sqrt(1/3).
    swapped = [tracks({7: truth[f, int(f >= 30)], 9: truth[f, int(f < 30)]}) for f in range(60)]
    figures = hota(frames, swapped)
    assert figures["deta"] == pytest.approx(1.0) and figures["assa"] == pytest.approx(1 / 3, abs=1e-4)
    assert figures["hota"] == pytest.approx(np.sqrt(1 / 3), abs=1e-4)


def test_hota_counts_the_distance_thresholds_a_track_meets():
    # Every track 110 mm off its person: a similarity of 1 - 110/500 = 0.78, which meets the 15 thresholds
    # alpha = 0.05 ... 0.75 of trackeval's 19 and misses 0.80 ... 0.95 (there the track is a miss and a false
    # positive). HOTA is the mean over thresholds: 15/19.
    truth = walkers(20)
    off = [tracks({0: truth[f, 0] + [0, 110, 0], 1: truth[f, 1] + [0, 0, 110]}) for f in range(20)]
    figures = hota(frames_of(truth), off)
    assert figures["hota"] == pytest.approx(15 / 19, abs=1e-4)
    assert figures["hota_at_half"] == pytest.approx(1.0)


def test_a_track_on_nobody_is_a_phantom_with_its_longest_time_and_one_on_an_unannotated_person_is_not():
    truth = walkers(45, persons=1)
    table = np.full((NUM_JOINTS, 3), 5000.0)  # far from everyone
    # Track 3 follows the person; track 4 sits on the table in frames 10-29 (20 frames = 1.33 s), then on the
    # person in 30-34 (a break), then on the table again in 35-39 (5 frames).
    hyps = []
    for f in range(45):
        h = {3: truth[f, 0]}
        if 10 <= f < 30 or 35 <= f < 40:
            h[4] = table
        elif 30 <= f < 35:
            h[4] = truth[f, 0] + 50
        hyps.append(tracks(h, seed=f))
    figures = phantoms(frames_of(truth), hyps)
    assert figures == {"phantom_tracks": 1, "on_nobody_track_frames": 25,
                       "longest_on_nobody_s": pytest.approx(20 / FPS, abs=1e-3), "longest_on_nobody_track": 4}  # fmt: skip
    # The same track on a person in view whom the ground truth leaves unannotated is on somebody.
    beside = np.broadcast_to(table, (45, 1, NUM_JOINTS, 3))
    assert phantoms(frames_of(truth, ignore=beside), hyps)["on_nobody_track_frames"] == 0
    # score reports them beside MOTA and IDF1, and the 1 s goal reads them.
    figures = score(frames_of(truth), hyps, [0.1] * 45)
    assert figures["phantom_tracks"] == 1 and figures["longest_on_nobody_s"] > 1.0
    assert figures["false_positives"] == 25 + 5 and figures["hota"] < 1.0  # + its 5 frames as a second track


def test_breakdown_gives_every_untracked_person_frame_and_false_track_its_reason():
    from pipeline.track import Tracker
    from pipeline.track_eval import FALSE, MISSED, breakdown
    from posenet.synth.poses import PoseParams, build_pose

    body = build_pose(PoseParams())[:NUM_JOINTS]  # (J, 3) a standing adult, z up, mm
    at = {name: body + np.array([x, y, 0.0]) for name, x, y in [
        ("a", 0, 0), ("d", 0, 100), ("g", 0, -150),  # d shares a's skeleton; g has its own, 15 cm from a's
        ("b", 3000, 0), ("c", -3000, 0), ("ghost", 0, 3000), ("unannotated", 0, -3000),
    ]}  # fmt: skip
    annotated, skeletons = ["a", "b", "c", "d", "g"], ["a", "c", "g", "ghost", "unannotated"]
    spread = np.array([[900.0 if k == "c" else 90.0] * NUM_JOINTS for k in skeletons])  # c: too unsure
    frames = [
        SequenceFrame(f / FPS, np.arange(len(annotated)), np.array([at[k] for k in annotated]),
                      np.array([at[k] for k in skeletons]), spread, ignore_joints=at["unannotated"][None])
        for f in range(10)
    ]  # fmt: skip
    out = breakdown(frames, Tracker())
    assert out["person_frames"] == 50
    assert out["tracked"] == 8  # a, from its third frame (birth_hits)
    assert (
        out["missed"]
        == {
            **dict.fromkeys(MISSED, 0),
            "own skeleton on a tentative track": 2,  # a's first two frames
            "no skeleton within the gate": 10,  # b
            "own skeleton not tracked: spread": 10,  # c
            "only a neighbour's skeleton": 10,  # d
            "own skeleton near a neighbour's track": 10,  # g: the duplicate rule takes it for a second skeleton of a
        }
    )
    assert out["tracked"] + sum(out["missed"].values()) == out["person_frames"]
    # the ghost's track from its third frame; the unannotated person's track is left out, as in the evaluation
    assert out["false_positives"] == {**dict.fromkeys(FALSE, 0), "on nobody": 8}


def test_switches_tell_a_swap_on_the_spot_from_a_lost_track_and_a_new_one(monkeypatch, capsys):
    import sys
    from pathlib import Path

    from pipeline.track_eval import switches

    monkeypatch.syspath_prepend(str(Path(__file__).parents[2] / "benchmarks"))
    sys.modules.pop("tracking", None)
    from tracking import print_switches

    truth = walkers(60)
    frames = frames_of(truth)
    # Persons 0 and 1 swap tracks 7 and 9 at frame 30; person 0 then loses its track (9) in frames 40-44 and comes
    # back on a new track 11, while track 9 is gone.
    hyps = []
    for f in range(60):
        h = {7: truth[f, int(f >= 30)]}
        if f < 40:
            h[9] = truth[f, int(f < 30)]
        elif f >= 45:
            h[11] = truth[f, 0]
        hyps.append(tracks(h, seed=f))
    events = switches(frames, hyps)
    assert [(e["frame"], e["person"], e["from_track"], e["to_track"]) for e in events] == [
        (30, 0, 7, 9), (30, 1, 9, 7), (45, 0, 9, 11),
    ]  # fmt: skip
    swap_0, swap_1, new = events
    assert swap_0["to_track_was"] == 1 and swap_1["to_track_was"] == 0  # each took the other's track
    assert swap_0["from_track_reported"] and swap_0["unmatched_frames"] == 0  # a swap on the spot
    assert new["to_track_was"] is None and not new["from_track_reported"]  # a lost track, then a new one
    assert new["unmatched_frames"] == 5 and new["time_s"] == pytest.approx(45 / FPS, abs=1e-3)
    assert len(events) == score(frames, hyps, [0.1] * 60)["id_switches"]
    assert score(frames, hyps, [0.1] * 60, switch_events=True)["switch_events"] == events  # one matching for both
    # benchmarks/tracking.py --switches prints one line each
    assert print_switches(1, events) == events
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3 and lines[2] == (
        "sequence 1 frame 45 (3.0 s): person 0, track 9 -> 11 (a new track, after 5 frames without a track; "
        "track 9 not reported)"
    )
