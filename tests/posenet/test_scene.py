"""posenet.scene: the one scene contract, and PoseEstimator.predict on one scene or a batch of them."""

import numpy as np
import pytest
import torch
from tiny_scenes import write_dataset

from posenet.data.mvor import MvorDataset
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import Scene, SceneView


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny_scene")
    return list(MvorDataset(root, write_dataset(root, {1: 3}, persons=3, seed=5)))


def test_a_readers_view_is_the_scene_view_a_scene_takes(samples):
    view = samples[0].views[0]
    assert isinstance(view, SceneView)
    color, depth, camera = view  # unpacks like the tuple it once was
    assert color is view.color and depth is view.depth and camera is view.camera
    assert (view.height, view.width) == depth.shape
    scene = Scene.from_person_boxes([tuple(v) for v in samples[0].views], [])  # tuples are converted
    assert all(type(v) is SceneView and v.depth is s.depth for v, s in zip(scene.views, samples[0].views, strict=True))


@pytest.mark.parametrize("which", ["annotated", "boxed"])
def test_from_sample_keeps_the_samples_boxes_ids_and_poses(samples, which):
    sample = samples[0]
    scene = Scene.from_sample(sample, which)
    assert scene.id == sample.id and len(scene.views) == len(sample.views)
    assert all(
        isinstance(v, SceneView) and v.depth is s.depth
        for v, s in zip(scene.views, sample.views, strict=True)
    )
    assert scene.boxes.shape == (scene.num_persons, 3, 4) and scene.num_persons > 0
    for p, pid in enumerate(scene.person_ids.tolist()):
        for v, box in enumerate(sample.person_boxes(pid)):
            assert bool(scene.has_box[p, v]) == (box is not None)
            if box is not None:
                np.testing.assert_array_equal(scene.boxes[p, v].numpy(), np.asarray(box, np.float32))
        k = list(sample.person_ids).index(pid)
        np.testing.assert_array_equal(scene.poses[p].numpy(), sample.poses[k])
        np.testing.assert_array_equal(scene.valid[p].numpy(), sample.valid[k])
    torch.testing.assert_close(scene.support, scene.has_box.sum(1))


def test_person_boxes_give_the_same_scene_as_the_sample(samples):
    sample = samples[0]
    ref = Scene.from_sample(sample, "boxed")
    ids = ref.person_ids.tolist()
    scene = Scene.from_person_boxes(sample.views, [sample.person_boxes(i) for i in ids], ids, sample.id)
    for name in ("boxes", "has_box", "person_ids"):
        assert torch.equal(getattr(scene, name), getattr(ref, name))
    assert scene.poses.shape == (len(ids), 10, 3) and not scene.valid.any()  # no truth given


def test_construction_errors_name_the_problem(samples):
    views = samples[0].views
    with pytest.raises(ValueError, match=r"person 0 has 2 box entries, expected one per view \(3\)"):
        Scene.from_person_boxes(views, [[None, None]])
    with pytest.raises(ValueError, match="person 1, view 2: box must be finite xyxy"):
        Scene.from_person_boxes(views, [[None] * 3, [None, None, [10, 10, 5, 20]]])
    with pytest.raises(ValueError, match="person 0, view 0: box must be finite"):
        Scene.from_person_boxes(views, [[[0, 0, float("nan"), 5], None, None]])
    with pytest.raises(ValueError, match=r"boxes \(P, 3, 4\).*got \(2, 2, 4\)"):
        Scene(views, torch.zeros(2, 2, 4), torch.zeros(2, 2, dtype=torch.bool), torch.arange(2))
    with pytest.raises(ValueError, match=r"poses \(P, J, 3\)"):
        Scene(
            views, torch.zeros(1, 3, 4), torch.ones(1, 3, dtype=torch.bool), [0], poses=torch.zeros(2, 10, 3)
        )
    with pytest.raises(ValueError, match="at least one view"):
        Scene.from_person_boxes([], [])
    with pytest.raises(ValueError, match="'annotated' or 'boxed'"):
        Scene.from_sample(samples[0], "all")
    samples[0].views[1].depth, depth = None, samples[0].views[1].depth
    try:
        with pytest.raises(ValueError, match="every view needs a depth image"):
            Scene.from_sample(samples[0])
    finally:
        samples[0].views[1].depth = depth


def _estimator(mode: str, flip: bool) -> PoseEstimator:
    torch.manual_seed(0)
    inputs = InputConfig(mode=mode, crop_size=32, image_size=(80, 60), train_crop=(64, 48))
    return PoseEstimator(
        PoseNet(ModelConfig(inputs=inputs, base=8, depth=2, precision="fp32", flip_test=flip))
    )


@pytest.mark.parametrize("mode,flip", [("crop", False), ("full", False), ("crop", True)])
def test_a_batch_of_scenes_equals_each_scene_alone(samples, mode, flip):
    est = _estimator(mode, flip)
    scenes = [Scene.from_sample(s, "boxed") for s in samples]
    empty = Scene.from_person_boxes(samples[0].views, [])
    batch = est.predict([scenes[0], empty, *scenes[1:]], return_heatmaps=True)
    assert len(batch) == len(scenes) + 1 and batch[1].joints.shape == (0, 10, 3)
    for scene, together in zip(scenes, [batch[0], *batch[2:]], strict=True):
        alone = est.predict(scene, return_heatmaps=True)
        for name in ("joints", "spread_mm", "confidence", "heatmaps"):
            torch.testing.assert_close(getattr(together, name), getattr(alone, name), atol=1e-3, rtol=1e-4)
        assert torch.equal(together.has_points, alone.has_points) and torch.equal(together.valid, alone.valid)
    assert est.predict([]) == []
