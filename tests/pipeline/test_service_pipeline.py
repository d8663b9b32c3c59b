"""The pipeline without HTTP: grouping by ids or by the matcher, batched == single, offline predictions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from conftest import write_tiny_mvor
from service_harness import tiny_checkpoints

from detector.infer import PersonDetector
from pipeline.matching import box_centres_3d, valid_combinations
from pipeline.two_stage import PipelineConfig, ScenePipeline, group_by_ids
from posenet.cameras import Camera
from posenet.data.mvor import MvorDataset
from posenet.evaluation.evaluate import evaluate
from posenet.net.infer import PoseEstimator
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import SceneView


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    torch.manual_seed(0)
    cfg = ModelConfig(precision="fp32")  # float32 so that batched and single runs agree to rounding
    pose = PoseEstimator(PoseNet(cfg), {"model": dataclasses.asdict(cfg)})
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny"), days=(1,), frames_per_day=2)
    # The paper's centre matcher: these tests compare its groups (the skeleton matcher, the default, groups by a
    # random network's skeletons here; it has its own tests in tests/pipeline/test_skeleton_matching.py).
    return (
        ScenePipeline(pose, config=PipelineConfig(matcher="centres")),
        data,
        MvorDataset(data.root, data.gt),
    )


def test_group_by_ids():
    ids, groups = group_by_ids([np.array([4, 2]), np.array([], np.int64), np.array([2])])
    assert ids == [2, 4] and groups == [[1, -1, 0], [0, -1, -1]]


def test_batched_persons_equal_single_runs_and_matcher_equals_ids(setup):
    pipe, _, ds = setup
    sample = ds[0]
    views = sample.views
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
    views = ds[0].views
    empty = [np.zeros((0, 4), np.float32)] * 3
    assert pipe.run(views, empty).persons == []
    with pytest.raises(ValueError, match="no detector"):
        pipe.run(views)


def test_crowded_boxes_are_refused_before_matching_explodes(setup):
    pipe, _, _ = setup
    rng = np.random.default_rng(0)
    cams = [Camera.create(500.0, 500.0, 320.0, 240.0) for _ in range(4)]
    views = [SceneView(None, np.full((480, 640), 3000, np.uint16), c) for c in cams]
    # The bound holds: it is never below the number of combinations the matcher really enumerates.
    for _ in range(5):
        corners = [np.sort(rng.uniform(0, 600, (int(rng.integers(0, 6)), 2, 2)), axis=1) for _ in cams]
        boxes = [c.reshape(-1, 4) + [0, 0, 20, 20] for c in corners]  # (K, 4) with x1 > x0, y1 > y0
        centres, view = box_centres_3d(boxes, [v.depth for v in views], cams)
        enumerated = len(view) + sum(len(m) for m, _ in valid_combinations(centres, view, 750.0))
        assert pipe._combination_bound(boxes, views) >= enumerated
    # 4 views of 40 boxes at the same spot: 40^4 combinations would take gigabytes; refused at once instead.
    same = [np.tile([[100.0, 100.0, 200.0, 300.0]], (40, 1))] * 4
    with pytest.raises(ValueError, match="too crowded"):
        pipe.run(views, same)


def test_too_many_reference_persons_are_refused(setup):
    pipe, _, ds = setup
    views = ds[0].views
    boxes = [np.tile([[10.0, 10.0, 60.0, 90.0]], (33, 1))] + [np.zeros((0, 4))] * 2
    ids = [np.arange(33), np.zeros(0, np.int64), np.zeros(0, np.int64)]
    with pytest.raises(ValueError, match="33 persons, more than the limit of 32"):
        pipe.run(views, boxes, ids)


def test_run_sample_in_detector_mode_associates_ids(tmp_path, setup):
    pipe, data, ds = setup
    _, det = tiny_checkpoints(tmp_path, detector=True)
    with_detector = ScenePipeline(pipe.pose, PersonDetector.from_checkpoint(det))
    result, preds = with_detector.run_sample(ds[0], reference_boxes=False)
    assert result.mode == "detector" and result.timings["detect"] > 0
    gt_ids = set(ds[0].person_ids.tolist())
    assert {p["person_id"] for p in preds} <= gt_ids and len(preds) == len({p["person_id"] for p in preds})


def test_detector_loads_only_when_its_weights_exist(tmp_path, monkeypatch):
    # load_detector=None (the service's default): no detector weights -> reference-box mode, not a failed start.
    import detector.infer

    pose, det = tiny_checkpoints(tmp_path)
    monkeypatch.setattr(detector.infer, "DEFAULT_WEIGHTS", tmp_path / "absent" / "default.safetensors")
    assert ScenePipeline.from_checkpoints(pose, None, load_detector=None).detector is None
    assert ScenePipeline.from_checkpoints(pose, det, load_detector=None).detector is not None
    with pytest.raises(FileNotFoundError):
        ScenePipeline.from_checkpoints(pose, None, load_detector=True)


def test_settings_reach_the_pipeline(monkeypatch):
    """ORPOSE_* knobs of the matcher become the pipeline's config; 0 turns the free-space rule off."""
    from service.app import pipeline_config
    from service.settings import Settings

    default = pipeline_config(Settings())
    assert default.skeleton_match.free_space_mm == 300.0 and default.candidate_score == 0.25
    monkeypatch.setenv("ORPOSE_FREE_SPACE_MM", "0")
    monkeypatch.setenv("ORPOSE_CANDIDATE_SCORE", "1")
    off = pipeline_config(Settings())
    assert off.skeleton_match.free_space_mm is None and off.candidate_score == 1.0
    monkeypatch.setenv("ORPOSE_FREE_SPACE_MM", "-5")
    with pytest.raises(ValueError, match="free_space_mm"):
        Settings()


def test_settings_reach_every_stream_s_tracker(monkeypatch):
    """ORPOSE_TRACK_* knobs become the streams' tracker config: defaults as pipeline.track's, 0 turns the unsure
    gate off, and a coast outside (0, 60] s is refused."""
    from pipeline.track import TrackerConfig
    from service.app import tracker_config
    from service.settings import Settings

    assert tracker_config(Settings()) == TrackerConfig()
    monkeypatch.setenv("ORPOSE_TRACK_MAX_COAST_S", "5")
    monkeypatch.setenv("ORPOSE_TRACK_UNSURE_GATE_MM", "0")
    changed = tracker_config(Settings())
    assert changed.max_coast_s == 5.0 and changed.unsure_gate_mm is None
    for bad in ("0", "61"):
        monkeypatch.setenv("ORPOSE_TRACK_MAX_COAST_S", bad)
        with pytest.raises(ValueError, match="track_max_coast_s"):
            Settings()
