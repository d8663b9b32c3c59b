"""The pipeline without HTTP: grouping by ids or by the matcher, batched == single, offline predictions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from conftest import write_tiny_mvor

from posenet.data.mvor import MvorDataset
from posenet.evaluate import evaluate
from posenet.infer import PoseEstimator
from posenet.model import ModelConfig, PoseNet
from service.pipeline import FrameView, ScenePipeline, group_by_ids


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    torch.manual_seed(0)
    cfg = ModelConfig(bf16=False)  # float32 so that batched and single runs agree to rounding
    pose = PoseEstimator(PoseNet(cfg), {"model": dataclasses.asdict(cfg)})
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny"), days=(1,), frames_per_day=2)
    return ScenePipeline(pose), data, MvorDataset(data.root, data.gt)


def test_group_by_ids():
    ids, groups = group_by_ids([np.array([4, 2]), np.array([], np.int64), np.array([2])])
    assert ids == [2, 4] and groups == [[1, -1, 0], [0, -1, -1]]


def test_batched_persons_equal_single_runs_and_matcher_equals_ids(setup):
    pipe, _, ds = setup
    sample = ds[0]
    views = [FrameView(v.color, v.depth, v.camera) for v in sample.views]
    keep = [v.box_person_ids >= 0 for v in sample.views]
    boxes = [v.boxes[k] for v, k in zip(sample.views, keep, strict=True)]
    ids = [v.box_person_ids[k] for v, k in zip(sample.views, keep, strict=True)]
    both = pipe.run(views, boxes, ids)
    assert both.mode == "reference_boxes" and [p.id for p in both.persons] == [0, 1]
    assert set(both.timings) == {"detect", "match", "pose"}
    for person in both.persons:
        alone = pipe.run(views, [b[i == person.id] for b, i in zip(boxes, ids, strict=True)],
                         [i[i == person.id] for i in ids]).persons  # fmt: skip
        assert len(alone) == 1
        np.testing.assert_allclose(alone[0].joints, person.joints, atol=1e-2)
        np.testing.assert_allclose(alone[0].confidence, person.confidence, atol=1e-2)
    # The 3D matcher groups the same boxes into the same persons (ids aside).
    matched = pipe.run(views, boxes)
    key = sorted((tuple(p.support), tuple(np.round(p.joints[0], 1))) for p in matched.persons)
    assert key == sorted((tuple(p.support), tuple(np.round(p.joints[0], 1))) for p in both.persons)


def test_run_sample_gives_evaluable_predictions(setup):
    pipe, data, ds = setup
    preds = [p for i in range(len(ds)) for p in pipe.run_sample(ds[i])[1]]
    result = evaluate(data.gt, preds)
    assert result["counts"]["missing"] == 0 and result["counts"]["unmatched_predictions"] == 0
    assert np.isfinite(result["overall"])


def test_no_boxes_and_no_detector(setup):
    pipe, _, ds = setup
    views = [FrameView(v.color, v.depth, v.camera) for v in ds[0].views]
    empty = [np.zeros((0, 4), np.float32)] * 3
    assert pipe.run(views, empty).persons == []
    with pytest.raises(ValueError, match="no detector"):
        pipe.run(views)
