"""Hard negatives: drawn by the random look beside what it drew before, never a person, clear of everyone."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from posenet.synth.__main__ import main
from posenet.synth.hard_negatives import CLEAR_MM, KINDS, _clearance, hard_negative
from posenet.synth.looks import Look
from posenet.synth.primitives import BOX, CAPSULE, CONE, OWNER_HARD_NEGATIVE
from posenet.synth.procedural import procedural_frame
from posenet.synth.rig import cam_to_world, random_rig
from posenet.synth.room import yaw_matrix
from posenet.synth.scene import render_frame
from posenet.synth.sequence import build_stage


def _scene(seed: int, hard_negatives: int):
    rng = np.random.default_rng([seed, 0])
    rig = random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 2)
    frame = procedural_frame(rng, enclose=cam_to_world(rig)[:, :3, 3])
    look = Look("random", np.random.default_rng([seed, 1]), hard_negatives=hard_negatives)
    for person in frame.persons:
        look.dress(person)
    return frame, rig, look.finish(frame, rig)


def _z_range(p) -> tuple[float, float]:
    """The lowest and highest z of primitive ``p``."""
    if p.kind in (CAPSULE, CONE):
        r = p.size[:2] if p.kind == CONE else (p.size[0], p.size[0])
        return min(p.a[2] - r[0], p.b[2] - r[1]), max(p.a[2] + r[0], p.b[2] + r[1])
    reach = np.abs(p.rotation[2] * p.size).sum() if p.kind == BOX else np.linalg.norm(p.rotation[2] * p.size)
    return p.center[2] - reach, p.center[2] + reach


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_stands_on_the_floor_at_a_person_like_size(kind):
    for seed in range(5):
        prims = hard_negative(
            kind, np.array([500.0, -300.0, 0.0]), yaw_matrix(0.7), np.random.default_rng(seed)
        )
        low, top = np.array([_z_range(p) for p in prims]).T
        low, top = low.min(), top.max()
        assert low > -60 and 500 < top < 2400, (kind, low, top)


def test_the_random_look_adds_them_after_everything_it_drew_before():
    for seed in range(3):
        before, _, stats0 = _scene(seed, 0)
        after, rig, stats = _scene(seed, 3)
        assert "hard_negatives" not in stats0 and stats["clutter"] == stats0["clutter"]
        assert 1 <= stats["hard_negatives"] <= 3
        n = len(before.room)
        assert [p.owner for p in after.room[:n]] == [p.owner for p in before.room]
        assert all(
            np.array_equal(a.center, b.center) for a, b in zip(after.room[:n], before.room, strict=True)
        )
        people = [pickle.dumps((p.shape, p.outfit)) for p in after.persons]
        assert people == [pickle.dumps((p.shape, p.outfit)) for p in before.persons]
        added = after.room[n:]
        owners = sorted({p.owner for p in added}, reverse=True)
        assert owners == [OWNER_HARD_NEGATIVE - k for k in range(stats["hard_negatives"])]
        joints = np.concatenate([p.points[:, :2] for p in after.persons])
        for owner in owners:
            assert _clearance([p for p in added if p.owner == owner], joints) >= CLEAR_MM


def test_they_are_seen_but_never_a_person():
    frame, rig, stats = _scene(1, 4)
    views = render_frame(frame, rig, np.random.default_rng(0))
    seen = {int(o) for v in views for o in np.unique(v.owner) if o <= OWNER_HARD_NEGATIVE}
    assert seen and len(seen) <= stats["hard_negatives"]
    for v in views:
        assert len(v.boxes) == len(frame.persons)  # no box, no keypoints for anything but the persons


def test_a_sequence_keeps_them_off_every_walk():
    rng = np.random.default_rng(5)
    rig = random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 2)
    look = Look("random", np.random.default_rng(6), hard_negatives=3)
    stage, stats = build_stage(np.random.default_rng(7), rig, 12, 15.0, 3, look)
    assert stats["hard_negatives"] >= 1
    added = [p for p in stage.room if p.owner <= OWNER_HARD_NEGATIVE]
    for k in range(12):
        walk = np.concatenate([p.points[:, :2] for p in stage.frame(k).persons])
        for owner in {p.owner for p in added}:
            assert _clearance([p for p in added if p.owner == owner], walk) >= CLEAR_MM


def test_the_cli_takes_them_in_the_random_look_only(tmp_path, capsys):
    tiny = ["--scenes", "1", "--days", "1", "--views", "2", "--seed", "3", "--quiet"]
    main(["--out", str(tmp_path / "r"), *tiny, "--hard-negatives", "2"])
    settings = json.loads((tmp_path / "r" / "annotations.json").read_text())["dataset_info"]["synthetic"]
    assert settings["hard_negatives"] == 2 and settings["look"] == "random"
    for bad, says in (
        (["--look", "alt"], "random and mesh looks only"),
        (["--hard-negatives", "-1"], "0 or more"),
    ):
        args = ["--out", str(tmp_path / "x"), *tiny, "--hard-negatives", "2", *bad]
        with pytest.raises(SystemExit, match=says):
            main(args)
    with pytest.raises(ValueError, match="hard_negatives"):
        Look("random", np.random.default_rng(0), hard_negatives=-1)
    assert Look("alt", np.random.default_rng(0), hard_negatives=3).hard_negatives == 0
