"""``auto`` precision on OpenVINO (``posenet.runtime.auto_int8``): int8 only for weights whose int8 cost is on
record and small, only where this machine measures it faster, decided once per machine, and never a failed start.

A small convolution network's real OpenVINO graph stands in for both sides of the comparison (an int8 graph
needs a calibration of a minute; the rule is what is tested here, and ``tests/posenet/test_int8.py`` tests the
quantization itself).
"""

from __future__ import annotations

import json

import pytest
import torch

from posenet.runtime import auto_int8
from posenet.runtime.execution import Precision
from posenet.runtime.graphs import OnnxRunner, export_onnx, installed

pytestmark = pytest.mark.skipif(not installed("openvino"), reason="OpenVINO is not installed")
BF16 = Precision("bf16", "the CPU computes bf16 natively", auto=True)


@pytest.fixture
def graph(tmp_path, monkeypatch):
    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Conv2d(7, 8, 3, padding=1), torch.nn.ReLU(), torch.nn.Conv2d(8, 10, 1))
    return export_onnx(net.eval(), [torch.zeros(2, 7, 96, 96)], ["x"], ["y"], {"x": {0: "n"}, "y": {0: "n"}},
                       "unet", {"test": 1}, tmp_path)  # fmt: skip


def _runner(graph, name="fp32"):
    return lambda: OnnxRunner(graph, "openvino", 1, Precision(name, name))


def _never():
    raise AssertionError("the int8 graph was built though auto may not take it")


def test_weights_without_a_recorded_cost_never_quantize(graph):
    runner, p = auto_int8.choose(graph, 1, BF16, _runner(graph), _never)
    assert p.name == "bf16" and p.auto and "not on record" in p.reason and "natively" in p.reason
    assert isinstance(runner, OnnxRunner)


def test_a_recorded_cost_above_the_bounds_never_quantizes(graph, monkeypatch):
    monkeypatch.setitem(auto_int8.KNOWN_COST, graph.stem, auto_int8.Cost(0.3, 0.0, "a test"))
    assert "+0.30 cm" in auto_int8.choose(graph, 1, BF16, _runner(graph), _never)[1].reason


@pytest.mark.parametrize(("int8_ms", "float_ms", "taken"), [(10.0, 13.0, True), (10.0, 11.0, False)])
def test_int8_is_taken_where_measured_faster_by_the_margin(graph, monkeypatch, int8_ms, float_ms, taken):
    monkeypatch.setitem(auto_int8.KNOWN_COST, graph.stem, auto_int8.Cost(0.09, -0.001, "a test"))
    decision = {"int8_ms": int8_ms, "float_ms": float_ms, "float": "bf16", "threads": 1, "measured": "now"}
    auto_int8.decision_path(graph, 1).write_text(json.dumps(decision))  # as a first start measured it
    runner, p = auto_int8.choose(graph, 1, BF16, _runner(graph), _runner(graph, "int8"))
    assert p.name == ("int8" if taken else "bf16") and runner.precision.name == p.name
    assert f"{float_ms / int8_ms:.2f}x" in p.reason and ("+0.09 cm" in p.reason) == taken


def test_the_first_start_measures_and_caches_the_decision(graph, monkeypatch):
    monkeypatch.setitem(auto_int8.KNOWN_COST, graph.stem, auto_int8.Cost(0.09, 0.0, "a test"))
    path = auto_int8.decision_path(graph, 1)
    assert not path.exists()
    _, p = auto_int8.choose(graph, 1, BF16, _runner(graph), _runner(graph, "int8"))
    measured = json.loads(path.read_text())
    assert measured["int8_ms"] > 0 and measured["float_ms"] > 0 and measured["threads"] == 1
    assert p.name in ("int8", "bf16") and "measured on this machine" in p.reason
    # a later start reads the decision: the same times, not measured again
    assert auto_int8.choose(graph, 1, BF16, _runner(graph), _runner(graph, "int8"))[1] == p


def test_a_failed_int8_build_keeps_the_float_graph(graph, monkeypatch):
    monkeypatch.setitem(auto_int8.KNOWN_COST, graph.stem, auto_int8.Cost(0.09, 0.0, "a test"))

    def broken():
        raise RuntimeError("calibration scenes could not be rendered")

    runner, p = auto_int8.choose(graph, 1, BF16, _runner(graph), broken)
    assert p.name == "bf16" and "could not be built or measured" in p.reason and "rendered" in p.reason
    assert runner.precision == p


def test_the_shipped_weights_have_their_int8_cost_on_record(tmp_path):
    """A new shipped checkpoint has a graph of its own: without a row in KNOWN_COST, ``auto`` silently stops taking
    int8 for it on every machine. Measure its cost (benchmarks/backend_accuracy.py) and add the row."""
    from detector.infer import DEFAULT_WEIGHTS as DETECTOR_WEIGHTS
    from detector.infer import PersonDetector
    from posenet.net.checkpoint import DEFAULT_WEIGHTS as POSE_WEIGHTS
    from posenet.net.infer import PoseEstimator

    depth_pose, depth_detector = (w.with_name("depth.safetensors") for w in (POSE_WEIGHTS, DETECTOR_WEIGHTS))
    networks = [
        PoseEstimator.from_checkpoint(),
        PersonDetector.from_checkpoint(),
        PoseEstimator.from_checkpoint(depth_pose),  # the depth-only pair
        PoseEstimator.from_checkpoint(POSE_WEIGHTS.with_name("frames.safetensors")),  # the per-frame option
        PersonDetector.from_checkpoint(depth_detector),
    ]
    for network in networks:
        stem = network.export(tmp_path).stem
        assert stem in auto_int8.KNOWN_COST, f"{stem}: the shipped weights' int8 cost is not on record"
        assert auto_int8.KNOWN_COST[stem].small
