"""The MVOR-format reader: the real annotation file's known counts, the tiny dataset, subsampling, errors."""

from __future__ import annotations

import json
import time
from collections import Counter

import cv2
import numpy as np
import pytest
import torch
from conftest import MVOR_CAMERAS_INFO, MVOR_CATEGORY

from posenet.cameras import Camera
from posenet.data.images import depth_file_name, subsample_depth
from posenet.data.mvor import MvorDataset, collate_samples, folds, load_annotations
from posenet.data.sample import Sample
from posenet.data.support import pose_support


# --------------------------------------------------------------------------- the real annotation file
@pytest.fixture(scope="module")
def mvor(mvor_json) -> MvorDataset:
    return MvorDataset(None, mvor_json)


def test_real_mvor_known_counts(mvor: MvorDataset) -> None:
    samples = list(mvor)
    assert len(samples) == 732
    assert sum(len(s.poses) for s in samples) == 1061
    assert mvor.days == [1, 2, 3, 4]
    assert Counter(s.day for s in samples) == {1: 57, 2: 330, 3: 223, 4: 122}
    support = Counter(x for s in samples for x in s.support.tolist())
    assert support == {1: 132, 2: 426, 3: 503}  # MVOR's published numbers
    assert sum(len(v.boxes) for s in samples for v in s.views) == 4699
    assert all(len(s.views) == 3 and [v.cam_index for v in s.views] == [0, 1, 2] for s in samples)
    assert all(s.valid.all() for s in samples)  # every real 3D joint is annotated
    assert sum(len(s.poses) == 0 for s in samples) == 103  # frames with boxes only
    assert all(s.poses.shape == (len(s.person_ids), 10, 3) == (*s.valid.shape, 3) for s in samples)


def test_real_support_rule_differs_from_view_counting_only_on_one_frame(mvor_annotations: dict) -> None:
    # Counting distinct views gives 132/428/501; only poses 636 and 637 (two persons both labelled 0) differ.
    support = pose_support(mvor_annotations)
    boxed = {(a["image_id"], a["person_id"]) for a in mvor_annotations["annotations"]}
    frames = {mv["id"]: [im["id"] for im in mv["images"]] for mv in mvor_annotations["multiview_images"]}
    views = [
        sum((i, p["person_id"]) in boxed for i in frames[p["image_ids"]])
        for p in mvor_annotations["annotations3D"]
    ]
    assert Counter(views) == {1: 132, 2: 428, 3: 501}
    differ = [
        p["id"] for p, s, v in zip(mvor_annotations["annotations3D"], support, views, strict=True) if s != v
    ]
    assert differ == ["636", "637"]


def test_test_fixtures_hold_the_real_calibration(mvor_annotations: dict) -> None:
    assert mvor_annotations["cameras_info"] == MVOR_CAMERAS_INFO
    category = mvor_annotations["categories"][0]
    assert {k: category[k] for k in MVOR_CATEGORY} == MVOR_CATEGORY


@pytest.mark.parametrize("subsample", [1, 2])
def test_real_3d_joints_project_onto_mvor_2d_keypoints(mvor_annotations: dict, subsample: int) -> None:
    ds = MvorDataset(None, mvor_annotations, subsample=subsample)
    distorted_cameras = [
        c.scale(1 / subsample)
        for c in Camera.from_mvor(mvor_annotations["cameras_info"], use_distortion=True)
    ]
    errors = {False: [], True: []}
    for sample in ds:
        for view in sample.views:
            for box_pid, kps in zip(view.box_person_ids, view.keypoints2d, strict=True):
                hits = np.flatnonzero(sample.person_ids == box_pid)
                if box_pid < 0 or len(hits) != 1:
                    continue
                joints = torch.as_tensor(sample.poses[hits[0]], dtype=torch.float64)
                seen = (kps[:, 2] > 0) & sample.valid[hits[0]]
                for distorted in (False, True):
                    camera = distorted_cameras[view.cam_index] if distorted else view.camera
                    uv = camera.project(joints).numpy()
                    errors[distorted] += np.linalg.norm(uv[seen] - kps[seen, :2], axis=1).tolist()
        if len(errors[False]) > 3000:
            break
    plain, distorted = np.median(errors[False]), np.median(errors[True])
    # MVOR's 3D poses were made without distortion: about 8 px at 640x480, and distortion makes it worse.
    assert plain < 10.0 / subsample
    assert distorted > plain


# --------------------------------------------------------------------------- the tiny dataset
def test_tiny_dataset_samples(tiny_mvor_dataset) -> None:
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations)
    assert len(ds) == 4 and ds.days == [1, 2]
    sample = ds[0]
    assert isinstance(sample, Sample) and sample.day == 1
    assert sample.id == "10010000000_10020000000_10030000000"
    assert len(sample.views) == 3 and [v.cam_index for v in sample.views] == [0, 1, 2]
    for view in sample.views:
        assert view.color.shape == (480, 640, 3) and view.color.dtype == np.uint8
        assert view.depth.shape == (480, 640) and view.depth.dtype == np.uint16
        assert view.camera.size == (640, 480)
        assert view.keypoints2d.shape == (len(view.boxes), 10, 3)
        assert view.boxes.dtype == np.float32 and view.box_person_ids.dtype == np.int64
    assert sample.poses.shape == (2, 10, 3) and sample.poses.dtype == np.float32
    assert sample.person_ids.tolist() == [0, 1]
    assert sample.support.tolist() == [3, 2]
    assert ds[1].support.tolist() == [3, 1]
    assert ds[1].valid[1].tolist() == [True] * 9 + [False]
    assert sample.views[1].box_person_ids.tolist().count(-1) == 1  # a box without identity is kept
    assert sample.person_boxes(1)[2] is None  # person 1 has no box in camera 3
    # The colour really is RGB: person 0 is drawn red.
    x0, y0, x1, y1 = sample.person_boxes(0)[0].astype(int)
    patch = sample.views[0].color[y0 + 2 : y1 - 1, x0 + 2 : x1 - 1].reshape(-1, 3)
    assert (np.median(patch, axis=0) == [200, 60, 60]).all()


@pytest.mark.parametrize("subsample", [1, 2, 4])
def test_keypoints_and_boxes_follow_the_cameras(tiny_mvor_dataset, subsample: int) -> None:
    ds = MvorDataset(
        tiny_mvor_dataset.root, tiny_mvor_dataset.annotations, subsample=subsample, modalities=()
    )
    for sample in ds:
        for view in sample.views:
            for pid, kps, box in zip(view.box_person_ids, view.keypoints2d, view.boxes, strict=True):
                if pid < 0:
                    continue
                p = int(np.flatnonzero(sample.person_ids == pid)[0])
                uv = view.camera.project(torch.as_tensor(sample.poses[p], dtype=torch.float64)).numpy()
                seen = kps[:, 2] > 0
                np.testing.assert_allclose(kps[seen, :2], uv[seen], atol=1e-3)
                assert (box[:2] <= uv[seen].min(0)).all() and (box[2:] >= uv[seen].max(0)).all()


def test_subsampling_matches_the_full_resolution_sample(tiny_mvor_dataset) -> None:
    full = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations)[2]
    half = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations, subsample=2)[2]
    for f, h in zip(full.views, half.views, strict=True):
        assert h.color.shape == (240, 320, 3) and h.depth.shape == (240, 320)
        assert (h.width, h.height) == (320, 240) and h.camera.size == (320, 240)
        np.testing.assert_array_equal(h.color, cv2.resize(f.color, (320, 240), interpolation=cv2.INTER_AREA))
        np.testing.assert_array_equal(h.depth, subsample_depth(f.depth, 2))
        torch.testing.assert_close(h.camera.intrinsics, f.camera.scale(0.5).intrinsics)
        np.testing.assert_allclose(h.boxes, (f.boxes + 0.5) * 0.5 - 0.5, atol=1e-4)
        annotated = f.keypoints2d[..., 2] > 0
        np.testing.assert_allclose(
            h.keypoints2d[annotated][:, :2], (f.keypoints2d[annotated][:, :2] + 0.5) * 0.5 - 0.5, atol=1e-4
        )
        assert (h.keypoints2d[~annotated] == 0).all()
    np.testing.assert_array_equal(half.poses, full.poses)  # 3D is untouched


def _depth_reference(depth: np.ndarray, s: int) -> np.ndarray:
    """Brute-force loop: the lower median of each block's non-zero pixels."""
    out = np.zeros((depth.shape[0] // s, depth.shape[1] // s), np.uint16)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            valid = np.sort(depth[i * s : (i + 1) * s, j * s : (j + 1) * s].ravel())
            valid = valid[valid > 0]
            out[i, j] = valid[(len(valid) - 1) // 2] if len(valid) else 0
    return out


@pytest.mark.parametrize("s", [2, 3])
def test_subsample_depth_never_mixes_valid_and_invalid(s: int) -> None:
    rng = np.random.default_rng(0)
    depth = rng.integers(500, 6000, (31, 47)).astype(np.uint16)
    depth[rng.random(depth.shape) < 0.4] = 0
    depth[:6, :6] = 0  # whole blocks without a valid pixel
    out = subsample_depth(depth, s)
    np.testing.assert_array_equal(out, _depth_reference(depth, s))
    assert (out[:2, :2] == 0).all()
    blocks = depth[: out.shape[0] * s, : out.shape[1] * s].reshape(out.shape[0], s, out.shape[1], s)
    assert ((blocks == out[:, None, :, None]).any(axis=(1, 3))).all()  # every output is a measured value


def test_subsample_depth_examples() -> None:
    # One valid pixel: kept. Four: the lower median (never the outlier 9000, nor the mean 4508). None: 0.
    depth = np.array([[1000, 0, 3000, 3010, 0, 0], [0, 0, 3020, 9000, 0, 0]], np.uint16)
    assert subsample_depth(depth, 2).tolist() == [[1000, 3010, 0]]
    extremes = np.array([[65535, 0, 1, 0], [0, 0, 65535, 65535]], np.uint16)  # the uint16 range's ends
    assert subsample_depth(extremes, 2).tolist() == [[65535, 65535]]
    assert subsample_depth(extremes, 2).tolist() == _depth_reference(extremes, 2).tolist()


def test_depth_file_name() -> None:
    assert depth_file_name("day1/cam2/color/000003.png") == "day1/cam2/depth/000003.png"
    with pytest.raises(ValueError, match="no 'color' folder"):
        depth_file_name("day1/cam2/rgb/000003.png")


def test_modalities_and_annotation_only_reading(tiny_mvor_dataset) -> None:
    root, ann = tiny_mvor_dataset.root, tiny_mvor_dataset.annotations
    depth_only = MvorDataset(root, ann, modalities=("depth",))[0]
    assert all(v.color is None and v.depth is not None for v in depth_only.views)
    for f in root.rglob("*.png"):
        f.unlink()  # annotation-only reading must not touch the images
    for ds in (
        MvorDataset(root, ann, modalities=()),
        MvorDataset(None, ann),
        MvorDataset(None, json.loads(ann.read_text())),
    ):
        sample = ds[3]
        assert all(v.color is None and v.depth is None for v in sample.views)
        assert sample.views[0].width == 640 and sample.views[0].height == 480
        assert sample.support.tolist() == [3, 1]


def test_days_and_folds(tiny_mvor_dataset) -> None:
    ds = MvorDataset(None, tiny_mvor_dataset.annotations, days=[2])
    assert len(ds) == 2 and ds.days == [2] and all(s.day == 2 for s in ds)
    assert all(i.startswith("2001") for i in ds.ids)
    with pytest.raises(ValueError, match=r"days \[3\] have no frames"):
        MvorDataset(None, tiny_mvor_dataset.annotations, days=[3])
    assert folds([2, 1]) == [((2,), 1), ((1,), 2)]
    assert folds() == [((2, 3, 4), 1), ((1, 3, 4), 2), ((1, 2, 4), 3), ((1, 2, 3), 4)]
    with pytest.raises(ValueError, match="at least two days"):
        folds([1])


def test_dataloader_with_collate(tiny_mvor_dataset) -> None:
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations, subsample=2)
    loader = torch.utils.data.DataLoader(ds, batch_size=3, collate_fn=collate_samples)
    batches = list(loader)
    assert [len(b) for b in batches] == [3, 1]
    assert all(isinstance(s, Sample) for b in batches for s in b)
    assert [s.id for b in batches for s in b] == ds.ids


def test_reading_a_frame_is_fast(tiny_mvor_dataset) -> None:
    # Noise compresses badly, like real photos: the PNG decode dominates.
    rng = np.random.default_rng(0)
    for f in tiny_mvor_dataset.root.glob("day1/cam*/color/000000.png"):
        cv2.imwrite(str(f), rng.integers(0, 256, (480, 640, 3), dtype=np.uint8))
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations, subsample=2)
    times = []
    for _ in range(5):
        t = time.perf_counter()
        ds[0]
        times.append(time.perf_counter() - t)
    # The target is well under 50 ms on a free core; the bound leaves room for a busy shared CI machine.
    assert np.median(times) < 0.2


# --------------------------------------------------------------------------- errors
def test_missing_image_names_the_file(tiny_mvor_dataset) -> None:
    (tiny_mvor_dataset.root / "day2/cam3/depth/000001.png").unlink()
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations)
    ds[2]  # other frames still read
    with pytest.raises(FileNotFoundError, match=r"day2/cam3/depth/000001\.png does not exist"):
        ds[3]


def test_wrong_image_size_names_the_file(tiny_mvor_dataset) -> None:
    cv2.imwrite(str(tiny_mvor_dataset.root / "day1/cam2/color/000000.png"), np.zeros((240, 320, 3), np.uint8))
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations)
    message = r"day1/cam2/color/000000\.png is 320x240 pixels, but the annotations say 640x480"
    with pytest.raises(ValueError, match=message):
        ds[0]
    # Without width/height in the image entries, the calibration's imagesize is the reference.
    gt = tiny_mvor_dataset.gt
    for image in gt["multiview_images"][0]["images"]:
        del image["width"], image["height"]
    with pytest.raises(ValueError, match=message):
        MvorDataset(tiny_mvor_dataset.root, gt)[0]


def test_8bit_depth_names_the_file(tiny_mvor_dataset) -> None:
    cv2.imwrite(str(tiny_mvor_dataset.root / "day1/cam1/depth/000001.png"), np.full((480, 640), 90, np.uint8))
    ds = MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations, modalities=("depth",))
    with pytest.raises(ValueError, match=r"day1/cam1/depth/000001\.png has dtype uint8 \(8-bit\).*16-bit"):
        ds[1]


def test_corrupt_image_names_the_file(tiny_mvor_dataset) -> None:
    (tiny_mvor_dataset.root / "day1/cam1/color/000000.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match=r"day1/cam1/color/000000\.png could not be decoded"):
        MvorDataset(tiny_mvor_dataset.root, tiny_mvor_dataset.annotations)[0]


def test_unknown_camera_names_the_file(tiny_mvor_dataset) -> None:
    gt = tiny_mvor_dataset.gt
    gt["multiview_images"][1]["images"][2]["cam_id"] = 7
    with pytest.raises(ValueError, match=r"day1/cam3/color/000001\.png.*unknown camera cam_id=7.*3 cameras"):
        MvorDataset(tiny_mvor_dataset.root, gt)


def test_bad_arguments_and_annotations(tiny_mvor_dataset, tmp_path) -> None:
    ann = tiny_mvor_dataset.annotations
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="subsample must be a positive integer"):
            MvorDataset(None, ann, subsample=bad)
    with pytest.raises(ValueError, match=r"unknown modalities \['rgb'\]"):
        MvorDataset(None, ann, modalities=("rgb",))
    with pytest.raises(FileNotFoundError, match="is not a folder"):
        MvorDataset(tmp_path / "nowhere", ann)
    with pytest.raises(FileNotFoundError, match="nowhere.json does not exist"):
        load_annotations(tmp_path / "nowhere.json")
    partial = tmp_path / "partial.json"
    partial.write_text(json.dumps({"images": []}))
    with pytest.raises(ValueError, match=r"partial\.json: not an MVOR-format annotation file, missing keys"):
        load_annotations(partial)
    gt = tiny_mvor_dataset.gt
    gt["annotations3D"][0]["keypoints3D"] = gt["annotations3D"][0]["keypoints3D"][:30]
    with pytest.raises(ValueError, match=r"annotations3D\[0\].*keypoints3D has 30 numbers"):
        MvorDataset(None, gt)
