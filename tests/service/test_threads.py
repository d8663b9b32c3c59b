"""torch's threads while serving (``service.app.torch_threads``): one where both networks run on an inference
runtime (torch then computes only small ops, where two OpenMP threads stall on a shared machine), ORPOSE_THREADS
where a network runs on torch."""

from __future__ import annotations

import pytest
from service_harness import tiny_checkpoints

from pipeline.two_stage import ScenePipeline
from posenet.runtime.graphs import installed
from service.app import torch_threads


@pytest.fixture(scope="module")
def pose(tmp_path_factory):
    return tiny_checkpoints(tmp_path_factory.mktemp("ckpt"), detector=False)[0]


def test_torch_keeps_its_threads_where_a_network_runs_on_torch(pose):
    pipe = ScenePipeline.from_checkpoints(pose, load_detector=False, backend="torch", threads=2)
    assert pipe.pose.backend.name == "torch" and torch_threads(2, pipe) == 2


@pytest.mark.skipif(not installed("onnxruntime"), reason="ONNX Runtime is not installed")
def test_one_torch_thread_where_every_network_runs_on_a_runtime(pose, tmp_path, monkeypatch):
    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    pipe = ScenePipeline.from_checkpoints(pose, load_detector=False, backend="onnxruntime", threads=2)
    assert pipe.pose.backend.name == "onnxruntime" and torch_threads(2, pipe) == 1
