"""Admission by cost in the pipeline: persons x views x network-input pixels within ``max_pose_pixels``."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import write_tiny_mvor
from service_harness import tiny_checkpoints

from pipeline.skeleton_matching import SkeletonMatchConfig
from pipeline.two_stage import PipelineConfig, ScenePipeline
from posenet.data.mvor import MvorDataset

CROP = 96 * 96  # the cpu preset's network input


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    pose, det = tiny_checkpoints(tmp_path_factory.mktemp("ckpt"))
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny"), days=(1,), frames_per_day=1)
    sample = MvorDataset(data.root, data.gt)[0]
    views = sample.views  # 3 views
    return pose, det, views


def test_reference_boxes_beyond_the_budget_are_refused_with_the_setting(frame):
    pose, _, views = frame
    pipe = ScenePipeline.from_checkpoints(pose, None, config=PipelineConfig(max_pose_pixels=3 * 4 * CROP))
    boxes = [np.array([[20.0 + 8 * p, 60.0, 300.0 + 8 * p, 440.0] for p in range(5)], np.float32)] * 3
    ids = [np.arange(5)] * 3
    with pytest.raises(ValueError, match=r"5 persons, more than the 4 that fit .* ORPOSE_MAX_POSE_PIXELS"):
        pipe.run(views, boxes, ids)
    assert len(pipe.run(views, [b[:4] for b in boxes], [i[:4] for i in ids]).persons) == 4  # 4 fit


def test_detector_mode_keeps_the_persons_that_fit(frame):
    pose, det, views = frame
    # The random tiny networks' one-view "persons" lie in free space for the other views: the matcher's step 7
    # would drop them (tests/pipeline/test_skeleton_matching.py). Admission by cost is tested here, so it is off.
    keep_all = SkeletonMatchConfig(free_space_mm=None)
    free = ScenePipeline.from_checkpoints(pose, det, config=PipelineConfig(skeleton_match=keep_all))
    found = len(free.run(views).persons)
    assert found >= 2, "the random tiny detector finds several persons in this frame"
    capped = ScenePipeline(
        free.pose, free.detector, PipelineConfig(max_pose_pixels=3 * 1 * CROP, skeleton_match=keep_all)
    )
    assert len(capped.run(views).persons) == 1  # the best-supported one
