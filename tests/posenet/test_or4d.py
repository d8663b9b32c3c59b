"""The 4D-OR reader on a tiny dataset the test writes: the reader tests the MVOR reader passes (mirrored from
``test_mvor.py``), 4D-OR's own conversion math, the extra joints, and the export that lets training, prediction and
evaluation run unchanged."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
from tiny_or4d import HEIGHT, WIDTH, write_tiny_or4d

from posenet.data.images import subsample_depth
from posenet.data.mvor import MvorDataset, collate_samples, folds
from posenet.data.or4d import EXTRA_JOINTS, Or4dDataset, Or4dSample
from posenet.data.sample import Sample


@pytest.fixture
def tiny(tmp_path):
    root = tmp_path / "4D-OR"
    truth = write_tiny_or4d(root)
    return root, truth


def test_tiny_dataset_samples(tiny):
    root, truth = tiny
    ds = Or4dDataset(root)
    assert len(ds) == 4 and ds.days == [1, 2]
    assert ds.ids == ["take1_000000", "take1_000001", "take2_000000", "take2_000001"]
    sample = ds[0]
    assert isinstance(sample, Sample) and isinstance(sample, Or4dSample) and sample.day == 1
    assert len(sample.views) == 6 and [v.cam_index for v in sample.views] == list(range(6))
    for view in sample.views:
        assert view.color.shape == (HEIGHT, WIDTH, 3) and view.color.dtype == np.uint8
        assert view.depth.shape == (HEIGHT, WIDTH) and view.depth.dtype == np.uint16
        assert view.camera.size == (WIDTH, HEIGHT)
        assert view.keypoints2d.shape == (len(view.boxes), 10, 3)
        assert view.boxes.dtype == np.float32 and view.box_person_ids.dtype == np.int64
    torch.testing.assert_close(
        sample.views[0].camera.extrinsics, torch.eye(4, dtype=torch.float64)
    )  # camera 0 frame
    assert sample.poses.shape == (2, 10, 3) and sample.poses.dtype == np.float32
    assert sample.extra_joints.shape == (2, 4, 3) and len(EXTRA_JOINTS) == 4
    assert sample.human_names == ["Patient", "human_0"] and sample.is_patient.tolist() == [True, False]
    assert sample.person_ids.tolist() == [0, 1] and sample.support.tolist() == [6, 6]
    assert sample.valid.all() and ds[1].extra_valid[1].tolist() == [True, True, True, False]  # no right foot
    # Colour really is RGB: camera c's wall is written as BGR (40 c, 90, 200 - 20 c), so red is 200 - 20 c.
    assert abs(int(np.median(sample.views[1].color[..., 0])) - 160) <= 3


def test_joints_follow_4dor_conversion(tiny):
    # The reader's 3D joints and cameras give the pixels 4D-OR's own loader math gives (re-done here from the files).
    root, truth = tiny
    ds = Or4dDataset(root, modalities=())
    folder = root / "export_holistic_take2_processed"
    labels = json.loads((folder / "annotations/000001.json").read_text())["labels"]
    head = next(lab for lab in labels if lab["humanName"] == "Patient" and lab["jointName"] == "head")
    loc = np.array([head["point3d"]["location"][k] for k in "xyz"])
    x500 = np.array(
        [loc[0] * 25, loc[2] * 25 + 1000, -loc[1] * 25]
    )  # coord_transform_human_pose_tool_to_OR_4D
    sample = ds[3]
    for v, view in enumerate(sample.views):
        value = json.loads((folder / f"camera{v + 1:02d}.json").read_text())["value0"]
        E = _pose(value["camera_pose"]) @ _pose(value["color2depth_transform"])
        cam = (np.linalg.inv(E) @ np.r_[x500 / 500, 1])[:3] * [
            1,
            -1,
            -1,
        ]  # world -> colour, then flip y and z
        cp = value["color_parameters"]
        want = [cam[0] / cam[2] * cp["fov_x"] + cp["c_x"], cam[1] / cam[2] * cp["fov_y"] + cp["c_y"]]
        got = view.camera.project(torch.as_tensor(sample.poses[0, :1], dtype=torch.float64))[0].numpy()
        np.testing.assert_allclose(got, want, atol=1e-3)
    # And the mm scale: the tiny dataset's head-to-foot height is 1630 mm.
    full = np.concatenate([sample.poses[0], sample.extra_joints[0]])
    assert abs(np.linalg.norm(full[0] - (full[12] + full[13]) / 2) - 1630) < 2


def _pose(entry):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    q, t = entry["rotation"], entry["translation"]
    T[:3, :3] = Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]]).as_matrix()
    T[:3, 3] = [t["m00"], t["m10"], t["m20"]]
    return T


@pytest.mark.parametrize("subsample", [1, 2, 4])
def test_keypoints_and_boxes_follow_the_cameras(tiny, subsample):
    ds = Or4dDataset(tiny[0], subsample=subsample, modalities=())
    for sample in ds:
        for view in sample.views:
            for pid, kps, box in zip(view.box_person_ids, view.keypoints2d, view.boxes, strict=True):
                uv = view.camera.project(torch.as_tensor(sample.poses[pid], dtype=torch.float64)).numpy()
                seen = kps[:, 2] > 0
                np.testing.assert_allclose(kps[seen, :2], uv[seen], atol=1e-3)
                assert (box[:2] <= uv[seen].min(0) + 1e-4).all() and (box[2:] >= uv[seen].max(0) - 1e-4).all()


def test_subsampling_matches_the_full_resolution_sample(tiny):
    full = Or4dDataset(tiny[0])[2]
    half = Or4dDataset(tiny[0], subsample=2)[2]
    for f, h in zip(full.views, half.views, strict=True):
        assert h.color.shape == (HEIGHT // 2, WIDTH // 2, 3) and h.camera.size == (WIDTH // 2, HEIGHT // 2)
        np.testing.assert_array_equal(
            h.color, cv2.resize(f.color, (WIDTH // 2, HEIGHT // 2), interpolation=cv2.INTER_AREA)
        )
        np.testing.assert_array_equal(h.depth, subsample_depth(f.depth, 2))
        torch.testing.assert_close(h.camera.intrinsics, f.camera.scale(0.5).intrinsics)
    np.testing.assert_array_equal(half.poses, full.poses)


def test_modalities_and_annotation_only_reading(tiny):
    root = tiny[0]
    depth_only = Or4dDataset(root, modalities=("depth",))[0]
    assert all(v.color is None and v.depth is not None for v in depth_only.views)
    for f in list(root.rglob("*.jpg")) + list(root.rglob("*.tiff")):
        f.unlink()
    sample = Or4dDataset(root, modalities=())[3]
    assert all(v.color is None and v.depth is None for v in sample.views)
    assert sample.views[0].width == WIDTH and sample.views[0].height == HEIGHT
    assert (
        len(Or4dDataset(root, modalities=(), annotated_only=False)) == 6
    )  # frame 2 of each take has no labels


def test_takes_folds_and_dataloader(tiny):
    ds = Or4dDataset(tiny[0], takes=[2], modalities=())
    assert len(ds) == 2 and ds.days == [2] and all(s.day == 2 for s in ds)
    with pytest.raises(ValueError, match=r"takes \[3\] are not in"):
        Or4dDataset(tiny[0], takes=[3])
    assert folds(Or4dDataset(tiny[0], modalities=()).days) == [((2,), 1), ((1,), 2)]
    loader = torch.utils.data.DataLoader(
        Or4dDataset(tiny[0], subsample=2), batch_size=3, collate_fn=collate_samples
    )
    assert [len(b) for b in loader] == [3, 1]


def test_errors_name_the_file(tiny):
    root = tiny[0]
    folder = root / "export_holistic_take1_processed"
    (folder / "depthimage/camera03_depthimage-000010.tiff").unlink()
    ds = Or4dDataset(root)
    ds[0]
    with pytest.raises(FileNotFoundError, match=r"camera03_depthimage-000010\.tiff does not exist"):
        ds[1]
    cv2.imwrite(str(folder / "colorimage/camera02_colorimage-000007.jpg"), np.zeros((60, 80, 3), np.uint8))
    with pytest.raises(
        ValueError, match=r"camera02_colorimage-000007\.jpg is 80x60 pixels, but the annotations say 160x120"
    ):
        ds[0]
    take2 = root / "export_holistic_take2_processed"
    cv2.imwrite(
        str(take2 / "depthimage/camera01_depthimage-000007.tiff"), np.full((HEIGHT, WIDTH), 9, np.uint8)
    )
    with pytest.raises(ValueError, match=r"camera01_depthimage-000007\.tiff has dtype uint8 \(8-bit\)"):
        ds[2]
    (take2 / "colorimage/camera01_colorimage-000010.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(ValueError, match=r"camera01_colorimage-000010\.jpg could not be decoded"):
        ds[3]
    with pytest.raises(ValueError, match="subsample must be a positive integer"):
        Or4dDataset(root, subsample=0)


def test_export_to_mvor_layout_reads_back_and_evaluates(tiny, tmp_path):
    from posenet.evaluation.evaluate import evaluate

    ds = Or4dDataset(tiny[0], modalities=())
    gt = ds.to_mvor(tmp_path / "mvor")
    mvor = MvorDataset(tmp_path / "mvor", tmp_path / "mvor/annotations.json")
    assert len(mvor) == len(ds) and mvor.days == [1, 2]
    for a, b in zip(mvor, ds, strict=True):
        np.testing.assert_allclose(a.poses, b.poses, atol=1e-3)
        assert a.support.tolist() == b.support.tolist()
        for va, vb in zip(a.views, b.views, strict=True):
            np.testing.assert_allclose(va.boxes, vb.boxes, atol=1e-3)
            torch.testing.assert_close(va.camera.extrinsics, vb.camera.extrinsics)
            assert (
                va.color.shape == (HEIGHT, WIDTH, 3) and va.depth.dtype == np.uint16
            )  # jpg / tiff behind .png links
    preds = [{"image_ids": p["image_ids"], "person_id": p["person_id"],
              "keypoints3D": np.asarray(p["keypoints3D"]).reshape(-1, 4)[:, :3].ravel().tolist()}
             for p in gt["annotations3D"]]  # fmt: skip
    result = evaluate(gt, preds)  # the ground truth scored against itself
    assert result["overall"] < 1e-3 and result["counts"]


def test_cli_reports_and_exports(tiny, tmp_path, capsys):
    from posenet.data.or4d import main

    assert main([str(tiny[0]), "--takes", "2", "--export-mvor", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "2 annotated frames in takes [2], 6 cameras" in out and "4 poses" in out
    assert "translations read as m" in out  # the conversion report of 4D-OR's camera files
    assert (tmp_path / "out/take2/cam6/depth/000001.png").is_symlink()
