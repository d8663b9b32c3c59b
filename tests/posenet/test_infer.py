import dataclasses

import cv2
import numpy as np
import pytest
import torch
from tiny_scenes import write_dataset

from posenet.cameras import Camera
from posenet.data.mvor import MvorDataset
from posenet.net.checkpoint import DEFAULT_WEIGHTS, load_checkpoint, save_checkpoint
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig, build_scene, resize_view
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import Scene


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny_infer")
    sample = MvorDataset(root, write_dataset(root, {1: 1}, persons=3, seed=1))[0]
    views = sample.views
    boxes = [[b if b is None else b.tolist() for b in sample.person_boxes(p)] for p in range(3)]
    boxes[2][1] = None  # one person unseen in one view
    return views, boxes


def _estimator(mode: str, precision: str = "fp32", seed: int = 0) -> PoseEstimator:
    torch.manual_seed(seed)
    inputs = InputConfig(mode=mode, crop_size=32, image_size=(80, 60), train_crop=(64, 48))
    model = PoseNet(ModelConfig(inputs=inputs, base=8, depth=2, precision=precision))
    with torch.no_grad():  # non-trivial BatchNorm statistics, so eval mode differs from train mode
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.2, 0.2)
                m.running_var.uniform_(0.5, 2.0)
    return PoseEstimator(model)


@pytest.mark.parametrize("mode", ["crop", "full"])
def test_batched_equals_per_person(scene, mode):
    views, boxes = scene
    est = _estimator(mode)
    together = est.predict(Scene.from_person_boxes(views, boxes))
    alone = [est.predict(Scene.from_person_boxes(views, [b])) for b in boxes]
    assert together.joints.shape == (3, 10, 3) and together.confidence.shape == (3, 10)
    torch.testing.assert_close(together.joints, torch.cat([a.joints for a in alone]), atol=1e-3, rtol=1e-5)
    torch.testing.assert_close(
        together.confidence, torch.cat([a.confidence for a in alone]), atol=1e-3, rtol=1e-4
    )
    assert together.has_points.all() and (together.confidence > 0).all()
    # one PersonPose record per person, the batch's rows
    records = together.persons()
    assert len(records) == 3 and len(empty_persons(est, views)) == 0
    for k, pose in enumerate(records):
        assert pose.joints.shape == (10, 3) and pose.joints.dtype == np.float64
        np.testing.assert_array_equal(pose.joints, together.joints[k].double().numpy())
        np.testing.assert_array_equal(pose.spread_mm, together.spread_mm[k].double().numpy())
        np.testing.assert_array_equal(pose.confidence, together.confidence[k].double().numpy())


def empty_persons(est, views):
    return est.predict(Scene.from_person_boxes(views, [])).persons()


@pytest.mark.parametrize("mode", ["full", "crop"])
def test_any_image_size_keeps_the_cameras_right(scene, mode):
    views, boxes = scene
    est = _estimator(mode)
    est.model.config.inputs.source_size = (80, 60)  # crop mode: crop from views of the training resolution
    big = []
    for color, depth, cam in views:  # the same scene at twice the resolution
        up = [cv2.resize(img, (160, 120), interpolation=cv2.INTER_NEAREST) for img in (color, depth)]
        big.append((*up, cam.scale(2.0)))
    big_boxes = [[None if b is None else [(x + 0.5) * 2 - 0.5 for x in b] for b in per] for per in boxes]
    a, b = (
        est.predict(Scene.from_person_boxes(views, boxes)),
        est.predict(Scene.from_person_boxes(big, big_boxes)),
    )
    torch.testing.assert_close(a.joints, b.joints, atol=1e-2, rtol=1e-5)


def test_heatmaps_for_pictures_and_empty_scene(scene):
    views, boxes = scene
    pred = _estimator("crop").predict(Scene.from_person_boxes(views, boxes), return_heatmaps=True)
    assert pred.heatmaps.shape == (3, 3, 10, 32 * 32) and pred.valid.shape == (3, 3, 32 * 32)
    assert not pred.valid[2, 1].any()  # no box, no votes
    empty = _estimator("crop").predict(Scene.from_person_boxes(views, []))
    assert empty.joints.shape == (0, 10, 3)


@pytest.mark.parametrize("mode", ["crop", "full"])
def test_box_heatmaps_equal_predict_with_views_without_boxes_and_without_any(scene, mode):
    """Each box lifted alone is its person predicted on that one box, whichever views hold no box; a frame
    without any box gives no box (the crops' per-view grids once failed on it)."""
    views, boxes = scene
    est = _estimator(mode)
    none = est.box_heatmaps(views, [np.zeros((0, 4), np.float32)] * len(views))
    assert none.num_boxes == 0 and none.single_view().joints.shape == (0, 10, 3)
    per_view = [np.zeros((0, 4), np.float32) for _ in views]
    per_view[0] = np.array([b[0] for b in boxes], np.float32)  # three boxes in view 0, none in the others
    alone = est.box_heatmaps(views, per_view).single_view()
    for k, person in enumerate(boxes):
        only = [person[0]] + [None] * (len(views) - 1)
        ref = est.predict(Scene.from_person_boxes(views, [only]))
        torch.testing.assert_close(alone.joints[k : k + 1], ref.joints, atol=1e-3, rtol=1e-5)


def test_bad_boxes_raise(scene):
    views, _ = scene
    est = _estimator("crop")
    with pytest.raises(ValueError, match="one per view"):
        est.predict(Scene.from_person_boxes(views, [[None, None]]))
    with pytest.raises(ValueError, match="xyxy"):
        est.predict(Scene.from_person_boxes(views, [[[10, 10, 5, 20], None, None]]))


def test_checkpoint_round_trip(scene, tmp_path):
    views, boxes = scene
    est = _estimator("crop", precision="bf16", seed=3)
    cfg = {"model": dataclasses.asdict(est.model.config), "preset": "test", "subsample": 1}
    save_checkpoint(tmp_path / "best", est.model, cfg)
    again = PoseEstimator.from_checkpoint(tmp_path / "best", precision="bf16")
    torch.testing.assert_close(
        again.predict(Scene.from_person_boxes(views, boxes)).joints,
        est.predict(Scene.from_person_boxes(views, boxes)).joints,
    )
    # The loader decides the precision, never the checkpoint (saved here by a bf16 model).
    assert PoseEstimator.from_checkpoint(tmp_path / "best", precision="fp32").precision.name == "fp32"
    model, config = load_checkpoint(tmp_path)  # a run folder: its best/
    assert config["preset"] == "test" and model.config.inputs.crop_size == 32


def test_missing_default_weights_say_how_to_get_them(tmp_path, monkeypatch):
    # A checkout or install without the shipped weights (they ship in this repo, so point the default elsewhere).
    import posenet.net.checkpoint

    monkeypatch.setattr(posenet.net.checkpoint, "DEFAULT_WEIGHTS", tmp_path / "default.safetensors")
    with pytest.raises(FileNotFoundError, match="posenet.training.train"):
        PoseEstimator.from_checkpoint(None)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        PoseEstimator.from_checkpoint("/nonexistent/model.safetensors")


def test_flip_averaging_averages_the_mirrored_pass(scene):
    views, boxes = scene
    est = _estimator("crop", seed=4)
    plain = est.predict(Scene.from_person_boxes(views, boxes))
    est.model.config.flip_test = True
    both = est.predict(Scene.from_person_boxes(views, boxes))
    s = Scene.from_person_boxes(views, boxes)
    with torch.inference_mode():
        mirrored = est.model(build_scene(s.views, s.boxes, s.has_box, est.model.config.inputs, mirror=True))
    assert not torch.allclose(mirrored.joints, plain.joints)
    torch.testing.assert_close(both.joints, (plain.joints + mirrored.joints) / 2, atol=1e-3, rtol=1e-5)


@pytest.mark.parametrize("mode", ["crop", "full"])
def test_a_single_view_works(scene, mode):
    views, boxes = scene
    pred = _estimator(mode).predict(Scene.from_person_boxes(views[:1], [[b[0]] for b in boxes]))
    assert pred.joints.shape == (3, 10, 3) and torch.isfinite(pred.joints).all()
    # with one view every joint lies on the lifted surface seen by camera 0, in front of it
    assert (pred.joints[..., 2] > 0).all()


def test_resize_view_keeps_projections_for_any_aspect():
    cam = Camera.create(90.0, 88.0, 49.5, 29.0, size=(100, 60))
    depth = np.full((60, 100), 2000, np.uint16)
    color = np.zeros((60, 100, 3), np.uint8)
    _, d2, cam2, (sx, sy) = resize_view(color, depth, cam, (80, 60))
    assert d2.shape == (48, 80) and cam2.size == (80, 48) and (sx, sy) == (0.8, 0.8)
    pts = torch.tensor([[100.0, -50.0, 2000.0], [-300.0, 200.0, 3500.0]], dtype=torch.float64)
    uv, uv2 = cam.project(pts), cam2.project(pts)
    torch.testing.assert_close(uv2, (uv + 0.5) * 0.8 - 0.5)


def test_boxed_persons_of_a_frame_without_identified_boxes(tmp_path):
    # A frame whose boxes all have person_id -1 (MVOR's box-only persons) has no one to predict, and no error.
    sample = MvorDataset(tmp_path, write_dataset(tmp_path, {1: 1}, persons=2, seed=2))[0]
    for view in sample.views:
        view.box_person_ids = np.full_like(view.box_person_ids, -1)
    persons = Scene.from_sample(sample, "boxed")
    assert persons.person_ids.numel() == 0 and persons.poses.shape == (0, 10, 3)


def test_shipped_default_weights_load_and_predict(scene):
    # The package's default weights (posenet/weights/default.*) load from their own config and run on any views.
    if not DEFAULT_WEIGHTS.is_file():
        pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
    est = PoseEstimator.from_checkpoint(None)
    views, boxes = scene
    out = est.predict(Scene.from_person_boxes(views, boxes))
    assert out.joints.shape == (3, 10, 3) and np.isfinite(np.asarray(out.joints)).all()
