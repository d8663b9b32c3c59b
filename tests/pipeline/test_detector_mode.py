"""benchmarks/detector_mode.py: --single-view (each reference box's single-view skeleton, scored against its person)
and --worst (the poses that lose most against reference boxes)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import write_tiny_mvor

from pipeline.two_stage import ScenePipeline
from posenet.data.mvor import MvorDataset
from posenet.data.support import pose_support
from posenet.evaluation.evaluate import prediction_record
from posenet.net.infer import PoseEstimator
from posenet.net.model import ModelConfig, PoseNet

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from detector_mode import FrameDetections, single_view_errors, worst_poses  # noqa: E402


def test_single_view_errors_equal_the_fused_error_of_persons_boxed_once(tmp_path):
    """One error row per annotated reference box; where a person has a box in one view only, its single-view
    skeleton is the person's skeleton, so its error is that of the pipeline's reference-box answer."""
    data = write_tiny_mvor(tmp_path, days=(1,), frames_per_day=2)
    ds = MvorDataset(data.root, data.gt)
    torch.manual_seed(0)
    cfg = ModelConfig(precision="fp32")
    pipe = ScenePipeline(PoseEstimator(PoseNet(cfg), {"model": dataclasses.asdict(cfg)}), None)
    checked = 0
    for i in range(len(ds)):
        sample = ds[i]
        views = sample.views
        err = single_view_errors(pipe, sample, views)
        boxed = sum(int(np.isin(v.box_person_ids, sample.person_ids).sum()) for v in sample.views)
        assert err.shape == (boxed, 2) and np.isfinite(err).all() and (err >= 0).all()
        result, _ = pipe.run_sample(sample, reference_boxes=True)
        order = [int(pid) for v in sample.views for pid in np.asarray(v.box_person_ids).reshape(-1)
                 if pid in sample.person_ids]  # fmt: skip
        for k, pid in enumerate(order):
            n = int(np.flatnonzero(sample.person_ids == pid)[0])
            if sample.support[n] != 1:
                continue
            person = next(p for p in result.persons if p.id == pid)
            d = np.linalg.norm(person.joints - sample.poses[n], axis=-1)[sample.valid[n]]
            np.testing.assert_allclose(err[k], [d.mean(), np.median(d)], rtol=1e-4, atol=0.05)
            checked += 1
    assert checked, "the tiny frames should hold a person boxed in one view"


def test_worst_poses_finds_the_poses_moved_and_their_share_of_the_excess(tmp_path):
    """Detected answers equal to the reference ones except two poses, moved by 30 and 10 cm: per support, those
    poses lead the list with the excess they were given, and hold all of it."""
    data = write_tiny_mvor(tmp_path, days=(1, 2), frames_per_day=3)
    gt = data.gt
    support = pose_support(gt)
    poses = gt["annotations3D"]
    rng = np.random.default_rng(0)
    joints = [np.asarray(p["keypoints3D"], float).reshape(-1, 4)[:10, :3] for p in poses]
    reference = [prediction_record(p["image_ids"], p["person_id"], j + rng.normal(0, 20, j.shape))
                 for p, j in zip(poses, joints, strict=True)]  # fmt: skip
    detected = [dict(r) for r in reference]
    moved = {0: 300.0, len(poses) - 1: 100.0}  # pose index -> mm along x
    for i, mm in moved.items():
        flat = np.asarray(detected[i]["keypoints3D"], float).reshape(-1, 3) + [mm, 0, 0]
        detected[i] = prediction_record(poses[i]["image_ids"], poses[i]["person_id"], flat)
    found = worst_poses(gt, reference, detected, None, n=2)
    assert sum(w["poses"] for w in found.values()) == len(poses)
    big, small = sorted(moved, key=moved.get, reverse=True)
    for i in (big, small):
        w = found[str(support[i])]
        listed = [(q["frame"], q["person_id"]) for q in w["worst"]]
        place = 1 if i == small and support[small] == support[big] else 0  # the larger move comes first
        assert listed[place] == (poses[i]["image_ids"], poses[i]["person_id"])
        assert w["worst"][place]["detected_cm"] > w["worst"][place]["reference_cm"]
        # every other pose is answered alike with either boxes: the moved ones hold all the excess
        assert w["share_of_worst"] == pytest.approx(1.0)
    for s, w in found.items():
        if all(str(support[i]) != s for i in moved):
            assert w["excess_cm"] == 0.0


def test_frame_detections_stand_in_for_the_detector_they_wrap():
    """The benchmark hands the pipeline one frame's boxes at any score: it is a detector.protocol.Detector, as the
    pipeline requires, and answers the wrapped detector's threshold."""
    from detector.protocol import Detections, Detector
    from posenet.runtime.execution import Precision
    from posenet.runtime.graphs import Backend

    class Fixed:
        score_threshold, input_width, needs_depth = 0.5, 160, True
        precision, backend = Precision("fp32", "test"), Backend("torch", "test")

        def detect(self, images, depths=None, score_threshold=None):
            scores = np.array([0.9, 0.6, 0.3], np.float32)
            keep = scores >= score_threshold
            return [Detections(np.zeros((3, 4), np.float32)[keep], scores[keep]) for _ in images]

    frame = FrameDetections(Fixed(), [dataclasses.make_dataclass("V", ["color", "depth"])(None, None)], 0.25)
    assert isinstance(frame, Detector) and frame.score_threshold == 0.5
    assert [len(d.scores) for d in frame.detect([None])] == [2]  # at the wrapped threshold
    assert [len(d.scores) for d in frame.detect([None], score_threshold=0.25)] == [3]
    ScenePipeline(object(), frame)  # accepted where a detector goes
