"""The renderer's CLI writes deterministic datasets that the MVOR reader reads like real MVOR."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from posenet.data.mvor import MvorDataset
from posenet.synth.__main__ import main

MVOR_JSON = Path(__file__).resolve().parents[2] / ".." / "shared" / "mvor" / "camma_mvor_2018.json"
REAL_KEYS = {
    "dataset_info", "multiview_images", "categories", "cameras_info", "images", "annotations3D", "info",
    "licenses", "annotations",
}  # fmt: skip


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*.png")) + [root / "annotations.json"]}  # fmt: skip


@pytest.fixture(scope="module")
def random_rig_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "a"
    summary = main(
        ["--out", str(out), "--scenes", "2", "--days", "2", "--views", "2", "--seed", "3", "--quiet"]
    )
    return out, summary


def test_same_seed_gives_the_same_bytes_and_another_seed_does_not(random_rig_dataset, tmp_path):
    out, _ = random_rig_dataset
    again = tmp_path / "b"
    main(["--out", str(again), "--scenes", "2", "--days", "2", "--views", "2", "--seed", "3", "--quiet"])
    assert _digest(out) == _digest(again)
    other = tmp_path / "c"
    main(["--out", str(other), "--scenes", "2", "--days", "2", "--views", "2", "--seed", "4", "--quiet"])
    a, c = _digest(out), _digest(other)
    assert a.keys() == c.keys() and all(a[k] != c[k] for k in a)


def test_layout_and_schema_match_real_mvor(random_rig_dataset):
    out, summary = random_rig_dataset
    ann = json.loads((out / "annotations.json").read_text())
    assert set(ann) == REAL_KEYS
    assert ann["dataset_info"]["synthetic"]["seed"] == 3
    assert summary["frames"] == 2 and summary["boxes"] == len(ann["annotations"])
    for im in ann["images"]:
        color = cv2.imread(str(out / im["file_name"]), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(out / im["file_name"].replace("/color/", "/depth/")), cv2.IMREAD_UNCHANGED)
        assert color.shape == (480, 640, 3) and color.dtype == np.uint8
        assert depth.shape == (480, 640) and depth.dtype == np.uint16
        day, cam, frame = str(im["id"])[0], int(str(im["id"])[1:4]), int(str(im["id"])[4:])
        assert im["file_name"] == f"day{day}/cam{cam}/color/{frame:06d}.png" and im["cam_id"] == cam
    for a in ann["annotations"]:
        assert len(a["keypoints"]) == 30 and len(a["bbox"]) == 4 and a["only_bbox"] == int(a["person_id"] < 0)
    for p in ann["annotations3D"]:
        assert len(p["keypoints3D"]) == 48
    # A new rig per day: day 2 uses cameras 3 and 4 of cameras_info.
    assert {im["cam_id"] for im in ann["images"] if im["day_id"] == 2} == {3, 4}
    assert len(ann["cameras_info"]["camParams"]["intrinsics"]) == 4


def test_the_mvor_reader_reads_what_the_renderer_writes(random_rig_dataset):
    out, _ = random_rig_dataset
    ann = json.loads((out / "annotations.json").read_text())
    ds = MvorDataset(out, out / "annotations.json", subsample=1)
    assert len(ds) == 2
    n_poses = 0
    for sample in ds:
        assert sample.poses.shape[1:] == (10, 3) and (sample.support >= 1).all()
        n_poses += len(sample.poses)
        for view in sample.views:
            assert view.color.shape == (480, 640, 3) and view.depth.dtype == np.uint16
            # The cameras the reader builds project the 3D joints onto the 2D keypoints the renderer wrote.
            for k, pid in enumerate(view.box_person_ids):
                if pid < 0:
                    continue
                pose = sample.poses[list(sample.person_ids).index(pid)]
                uv = view.camera.project(torch.as_tensor(pose, dtype=torch.float64)).numpy()
                kp = view.keypoints2d[k]
                seen = kp[:, 2] > 0
                assert np.abs(uv[seen] - kp[seen, :2]).max() < 0.6
    assert n_poses == len(ann["annotations3D"])


def test_workers_do_not_change_the_output(tmp_path):
    args = ["--scenes", "2", "--days", "1", "--views", "2", "--seed", "5", "--quiet"]
    main(["--out", str(tmp_path / "one"), *args])
    main(["--out", str(tmp_path / "two"), *args, "--workers", "2"])
    assert _digest(tmp_path / "one") == _digest(tmp_path / "two")


def test_bad_arguments_fail_clearly(tmp_path):
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--quiet"])
    with pytest.raises(SystemExit, match="MVOR annotation file not found"):
        main(["--out", str(tmp_path), "--scenes", "1", "--rig", "mvor", "--mvor-annotations", "/nope.json"])
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--scenes", "1", "--look", "shiny"])


@pytest.mark.skipif(not MVOR_JSON.is_file(), reason=f"MVOR annotations not found at {MVOR_JSON}")
def test_twin_keeps_mvor_rig_ids_poses_and_box_presence(tmp_path):
    real = json.loads(MVOR_JSON.read_text())
    out = tmp_path / "twin"
    main(["--out", str(out), "--from-mvor", str(MVOR_JSON), "--stride", "97", "--limit", "3", "--quiet"])
    ann = json.loads((out / "annotations.json").read_text())
    ext, real_ext = (np.array(a["cameras_info"]["camParams"]["extrinsics"]) for a in (ann, real))
    assert np.allclose(ext, real_ext, atol=1e-6)
    wanted = [mv["id"] for mv in real["multiview_images"][::97][:3]]
    assert [mv["id"] for mv in ann["multiview_images"]] == wanted
    real_poses = {(p["image_ids"], p["person_id"]): p["keypoints3D"] for p in real["annotations3D"]}
    ours = {(p["image_ids"], p["person_id"]): p["keypoints3D"] for p in ann["annotations3D"]}
    assert ours == {k: v for k, v in real_poses.items() if k[0] in wanted} and ours
    # Posed people have a box exactly where MVOR has one, and the boxes agree.
    boxes = {}
    for name, a in (("ours", ann), ("real", real)):
        boxes[name] = {
            (b["image_id"], b["person_id"]): b["bbox"] for b in a["annotations"] if b["person_id"] >= 0
        }
    keys = {(int(i), pid) for mv, pid in ours for i in mv.split("_")}
    assert {k for k in keys if k in boxes["ours"]} == {k for k in keys if k in boxes["real"]}
    ious = []
    for k in keys & boxes["real"].keys():
        (x, y, w, h), (X, Y, W, H) = boxes["ours"][k], boxes["real"][k]
        iw = max(min(x + w, X + W) - max(x, X), 0)
        ih = max(min(y + h, Y + H) - max(y, Y), 0)
        ious.append(iw * ih / (w * h + W * H - iw * ih))
    assert np.mean(ious) > 0.5


@pytest.mark.skipif(not MVOR_JSON.is_file(), reason=f"MVOR annotations not found at {MVOR_JSON}")
@pytest.mark.parametrize(("day", "frame"), [(4, 38), (1, 24)])
def test_twin_writes_each_person_once_where_mvor_reuses_an_id(tmp_path, day, frame):
    """MVOR gives two people id 0 in day 4 frame 38, and lists one pose twice in day 1 frame 24: the twin writes
    each real pose once, under an id of its own, with the boxes of the person it rendered from that pose."""
    real = json.loads(MVOR_JSON.read_text())
    mv_id = "_".join(f"{day}00{cam}0000{frame:03d}" for cam in (1, 2, 3))
    real_poses = {tuple(p["keypoints3D"]) for p in real["annotations3D"] if p["image_ids"] == mv_id}
    assert sum(p["image_ids"] == mv_id for p in real["annotations3D"]) == 2
    out = tmp_path / "twin"
    main(["--out", str(out), "--from-mvor", str(MVOR_JSON), "--mvor-days", str(day), "--stride", str(frame),
          "--limit", "2", "--quiet"])  # fmt: skip
    ann = json.loads((out / "annotations.json").read_text())
    ours = [p for p in ann["annotations3D"] if p["image_ids"] == mv_id]
    assert {tuple(p["keypoints3D"]) for p in ours} == real_poses and len(ours) == len(real_poses)
    ids = [p["person_id"] for p in ours]
    assert len(set(ids)) == len(ids)
    image_ids = {int(i) for i in mv_id.split("_")}
    boxes = [(b["image_id"], b["person_id"]) for b in ann["annotations"] if b["image_id"] in image_ids]
    assert len(set(boxes)) == len(boxes)  # no id twice in one view
    assert {pid for _, pid in boxes if pid >= 0} <= set(ids)
    # The reader pairs each pose with its own boxes: each pose's reference boxes lie around its projected joints.
    data = MvorDataset(out, out / "annotations.json")
    sample = data[data.ids.index(mv_id)]
    for k, pid in enumerate(sample.person_ids.tolist()):
        for view in sample.views:
            box = view.boxes[view.box_person_ids == pid]
            if len(box):
                uv = view.camera.project(
                    torch.as_tensor(sample.poses[k][sample.valid[k]], dtype=torch.float64)
                ).numpy()
                inside = (uv >= box[0, :2] - 20) & (uv <= box[0, 2:] + 20)
                assert inside.all(-1).mean() > 0.7
