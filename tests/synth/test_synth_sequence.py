"""Rendered sequences: persons move smoothly with fixed bodies and ids, and the MVOR reader reads the output."""

from __future__ import annotations

import json

import numpy as np

from posenet.data.mvor import MvorDataset
from posenet.skeleton import BONES, JOINT_INDEX
from posenet.synth.__main__ import main
from posenet.synth.rig import random_rig
from posenet.synth.sequence import build_stage
from posenet.synth.skeleton_full import NUM_MVOR_POINTS

TRUNK_SIDES = {(JOINT_INDEX[f"{s}_shoulder"], JOINT_INDEX[f"{s}_hip"]) for s in ("left", "right")}


def _stage(seed: int, frames: int = 150, persons: int = 4):
    rig = random_rig(np.random.default_rng(0), np.array([0.0, 0, 950]), np.array([4200.0, 3800, 1450]), 3)
    return build_stage(np.random.default_rng(seed), rig, frames, 15.0, persons)[0]


def _tracks(stage, frames: int) -> dict[int, dict[int, np.ndarray]]:
    """person id -> frame -> (12, 3) annotated points."""
    out: dict[int, dict[int, np.ndarray]] = {}
    for k in range(frames):
        for p in stage.frame(k).persons:
            if p.person_id >= 0:
                out.setdefault(p.person_id, {})[k] = p.points[:NUM_MVOR_POINTS]
    return out


def test_persons_move_smoothly_with_constant_bones_and_some_come_and_go():
    came_or_went = 0
    for seed in range(3):
        stage = _stage(seed)
        tracks = _tracks(stage, 150)
        assert set(tracks) == {0, 1, 2, 3}
        assert len(tracks[0]) == 150  # the first person stays all along
        moved = 0.0
        for frames in tracks.values():
            ks = sorted(frames)
            assert ks == list(range(ks[0], ks[-1] + 1))  # present in one stretch
            came_or_went += ks[0] > 0 or ks[-1] < 149
            pts = np.stack([frames[k] for k in ks])  # (T, 12, 3)
            step = np.linalg.norm(np.diff(pts, axis=0), axis=-1)  # (T-1, 12) mm per frame
            assert step.max() < 200, step.max()  # < 3 m/s at any joint
            bones = np.stack([np.linalg.norm(pts[:, a] - pts[:, b], axis=-1) for a, b in BONES], 1)
            # One body: limbs keep their lengths; only the trunk's sides (shoulder to hip) stretch as it twists.
            sides = [i for i, bone in enumerate(BONES) if bone in TRUNK_SIDES]
            limbs = [i for i in range(len(BONES)) if i not in sides]
            assert np.ptp(bones[:, limbs], axis=0).max() < 1e-6
            assert np.ptp(bones[:, sides], axis=0).max() < 60
            moved += np.linalg.norm(pts[-1, :10].mean(0) - pts[0, :10].mean(0))
        assert moved > 500  # people walk around, they do not stand still
        pelvis = {k: {f: p[4:6].mean(0)[:2] for f, p in v.items()} for k, v in tracks.items()}
        gaps = [np.linalg.norm(pelvis[a][f] - pelvis[b][f]) for a in pelvis for b in pelvis if a < b
                for f in set(pelvis[a]) & set(pelvis[b])]  # fmt: skip
        assert min(gaps) > 300  # nobody walks into anyone
    assert came_or_went >= 1


def test_same_seed_same_sequence():
    a, b = _stage(7, 30), _stage(7, 30)
    for k in (0, 17, 29):
        pa, pb = a.frame(k).persons, b.frame(k).persons
        assert [p.person_id for p in pa] == [p.person_id for p in pb]
        assert all(np.array_equal(x.points, y.points) for x, y in zip(pa, pb, strict=True))


def test_rendered_sequence_reads_as_mvor_with_stable_ids(tmp_path):
    out = tmp_path / "seq"
    summary = main(
        ["--out", str(out), "--sequence", "--frames", "3", "--persons", "2", "--views", "2", "--fps", "10",
         "--seed", "1", "--quiet"]
    )  # fmt: skip
    assert summary["frames"] == 3
    ann = json.loads((out / "annotations.json").read_text())
    mv = ann["multiview_images"]
    assert [(m["sequence"], m["frame_index"], m["timestamp_s"]) for m in mv] == [
        (1, 0, 0.0),
        (1, 1, 0.1),
        (1, 2, 0.2),
    ]
    assert ann["dataset_info"]["synthetic"]["mode"] == "sequence"
    ds = MvorDataset(out, ann)
    assert len(ds) == 3 and ds.ids == [m["id"] for m in mv]
    samples = [ds[k] for k in range(3)]
    ids = [set(s.person_ids.tolist()) for s in samples]
    assert ids[0] and all(i <= {0, 1} for i in ids)
    for a, b in zip(samples, samples[1:], strict=False):  # the same id is the same body, a step further
        for pid in set(a.person_ids.tolist()) & set(b.person_ids.tolist()):
            ja = a.poses[list(a.person_ids).index(pid)]
            jb = b.poses[list(b.person_ids).index(pid)]
            assert np.linalg.norm(ja - jb, axis=-1).max() < 300


def test_a_second_sequence_in_one_process_is_its_own(tmp_path):
    # The renderer keeps a sequence's stage per process; a second dataset rendered in the same process (as in a
    # test session or a notebook) must not reuse the first one's stage and its frame count.
    args = ["--sequence", "--persons", "2", "--views", "2", "--fps", "10", "--seed", "1", "--quiet"]
    assert main(["--out", str(tmp_path / "a"), "--frames", "2", *args])["frames"] == 2
    assert main(["--out", str(tmp_path / "b"), "--frames", "4", *args])["frames"] == 4
    fresh = json.loads((tmp_path / "b" / "annotations.json").read_text())
    assert [m["frame_index"] for m in fresh["multiview_images"]] == [0, 1, 2, 3]


def test_persons_barely_in_view_are_box_only_as_in_mvor(tmp_path):
    # Real MVOR gives a box a person id (2D keypoints, and the person a 3D pose) only when >= 5 of the 10 joints
    # are in the image and >= 4 visible. --annotate all (the renderer before version 1.2) annotated every box.
    args = ["--sequence", "--frames", "6", "--persons", "4", "--views", "2", "--fps", "2", "--seed", "10", "--quiet"]  # fmt: skip
    main(["--out", str(tmp_path / "mvor"), *args])
    main(["--out", str(tmp_path / "all"), *args, "--annotate", "all"])
    mvor, every = (json.loads((tmp_path / k / "annotations.json").read_text()) for k in ("mvor", "all"))
    assert [a["bbox"] for a in mvor["annotations"]] == [a["bbox"] for a in every["annotations"]]  # same boxes
    for png in (tmp_path / "all").rglob("*.png"):  # and the same images
        assert png.read_bytes() == (tmp_path / "mvor" / png.relative_to(tmp_path / "all")).read_bytes()
    frame_of = {im["id"]: m["id"] for m in mvor["multiview_images"] for im in m["images"]}
    labelled, only_box = set(), set()
    for a, b in zip(mvor["annotations"], every["annotations"], strict=True):
        flags = np.reshape(a["keypoints"], (10, 3))[:, 2]
        if a["person_id"] >= 0:
            assert (flags > 0).sum() >= 5 and (flags == 2).sum() >= 4 and a["only_bbox"] == 0
            assert a["person_id"] == b["person_id"] and a["keypoints"] == b["keypoints"]
            labelled.add((frame_of[a["image_id"]], a["person_id"]))
        elif b["person_id"] >= 0:  # annotated before, now box-only: too little of the person in view
            flags = np.reshape(b["keypoints"], (10, 3))[:, 2]
            assert (flags > 0).sum() < 5 or (flags == 2).sum() < 4
            assert a["only_bbox"] == 1 and not any(a["keypoints"])
            only_box.add((frame_of[a["image_id"]], b["person_id"]))
    assert only_box  # the seed holds such boxes
    poses = {(p["image_ids"], p["person_id"]) for p in mvor["annotations3D"]}
    assert poses == labelled  # a 3D pose exactly where some view annotates the person
    ignored = {(m["id"], p["person_id"]) for m in mvor["multiview_images"] for p in m["unannotated3D"]}
    assert ignored and ignored == only_box - labelled  # boxed persons without a 3D pose, for the evaluation
    before = {(p["image_ids"], p["person_id"]): p["keypoints3D"] for p in every["annotations3D"]}
    assert poses | ignored == set(before)
    for m in mvor["multiview_images"]:
        for p in m["unannotated3D"]:
            kept = np.reshape(before[(m["id"], p["person_id"])], (-1, 4))[:, :3]
            assert np.allclose(np.reshape(p["keypoints3D"], (-1, 4))[:, :3], kept, atol=1e-3)
    assert all("unannotated3D" not in m for m in every["multiview_images"])
