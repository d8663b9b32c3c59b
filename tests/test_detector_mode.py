"""benchmarks/detector_mode.py --single-view: each reference box's single-view skeleton, scored against its person."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch
from conftest import write_tiny_mvor

from posenet.data.mvor import MvorDataset
from posenet.infer import PoseEstimator
from posenet.model import ModelConfig, PoseNet
from posenet.scene import views_of
from service.pipeline import ScenePipeline

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
from detector_mode import single_view_errors  # noqa: E402


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
        views = views_of(sample)
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
